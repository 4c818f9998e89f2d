// The ray tracer of the viewer, one source for the GPU (trace.comp.glsl) and the CPU reference
// tracer (tracer/cpu_tracer.cpp): the same statements run in both (specs/viewer.md, "Tracing").
//
// The includer provides, before including this file:
//   FrameParams P;                       the frame's parameters
//   ISO_ADDRESS                          a type (macro) that locates a chunk's blob in the pool
//   ISO_ADDRESS blobBase(uint firstPage);      the blob that starts on this pool page
//   uint blobWord(ISO_ADDRESS base, uint word);   a word of a blob
//   uvec2 blobPair(ISO_ADDRESS base, uint word);  words `word` (even) and `word` + 1, one load
//   uvec4 chunkState(uint chunk);        the chunk table entry (ChunkEntry.state)
//   void requestChunk(uint chunk);       a ray needs this chunk (streaming)
//   void useChunk(uint chunk);           a ray went through this chunk (for the LRU)
//   vec3 environmentTexel(uint x, uint y);  linear RGB of the environment map
//   vec3 fusedMultiplyAdd(vec3 a, vec3 b, vec3 c);  a·b + c with one rounding
//   bool floatDistances();               records hold float32 distances (kOptionFloatDistances;
//                                        on the GPU a specialization constant, so no branch runs)
//   bool flatTraversal();                the loop shape of intersect (kOptionFlatTraversal; on
//                                        the GPU a specialization constant)
//   uint causticWord(uint word);         a word of the caustic map (shared.h, kCausticCells)
//   void depositCaustic(uint word, uint value);  an atomic add to one (caustics.h)
//   float lodPixels();                   the screen-space error (pixels) below which a coarser
//                                        level is drawn: P.lod.x, and -1 (the finest level
//                                        resident) for caustic photons, whose rays no pixel sees
//   bool splatsCompiled();               whether the splat code may run (on the GPU a
//                                        specialization constant; kOptionSplats says whether
//                                        it does)
//   bool pssCompiled();                  the same for a point set surface (kOptionPss), with
//                                        the accessors of pss.h and pss_volume.h (PssParams Q)
// and the macros ISO_INOUT(T) (GLSL `inout T`, C++ `T&`) and ISO_PRECISE (GLSL `precise`: no
// reassociation; C++ keeps the written order anyway).
//
// All coordinates are frame units: the octree root is the cube [0, 1)^3.
// Float literals carry an `f` so that the C++ build does the same single-precision arithmetic.
//
// The tracer is four files, in the order they build on each other:
//   records.h  chunks in the page pool, node records, corner records
//   cell.h     the surface inside one cell: the cubic along the ray and its first root
//   rays.h     rays through the octree to the first crossing, and the hit's attributes
//   pss.h      a point set surface (seed 001) and pss_volume.h the volume inside it
//   splats.h   the kept points as blended disks; the first hit on surface, splats, point set
//              surface, ground
//   shade.h    shading, shadows, reflections, refractions, one pixel
//   caustics.h photons from the lights through specular bounces into the caustic map
//   cone.h     camera rays a tile at a time: where the tile's rays start

#include "records.h"
#include "cell.h"
#include "rays.h"
#include "pss.h"
#include "pss_volume.h"
#include "splats.h"
#include "shade.h"
#include "caustics.h"
#include "cone.h"
