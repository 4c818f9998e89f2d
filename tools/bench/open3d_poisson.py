#!/usr/bin/env python3
"""The screened Poisson baseline of `tools/run bench accuracy`, as a new user of Open3D runs it.

    open3d_poisson.py normals SCAN.ply ORIENTED.ply [--neighbors K]
    open3d_poisson.py poisson ORIENTED.ply OUT_PREFIX --depth D [--trim Q]

`normals` drops any normals the scan has, estimates them by PCA over K neighbours (default 10) and
orients them with Open3D's consistent tangent plane propagation over K neighbours, and writes the
oriented points. `poisson` runs screened Poisson reconstruction at octree depth D on them and writes
OUT_PREFIX.ply (untrimmed) and OUT_PREFIX-trimmed.ply (vertices of density below the Q quantile
removed, default 0.01, as Open3D's documentation does). Each prints one JSON object: its seconds
per step and the process's peak resident memory. The benchmark runs the two steps as separate
processes so that each depth's peak memory is its own. Open3D is a benchmark baseline only; the
product never imports it.
"""
import argparse
import json
import resource
import sys
import time

import numpy as np
import open3d as o3d


def peak_rss_bytes():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def read_points(path):
    cloud = o3d.io.read_point_cloud(str(path))
    if len(cloud.points) == 0:
        sys.exit(f"open3d_poisson: {path}: no points read")
    return cloud


def normals(args):
    cloud = read_points(args.scan)
    cloud.normals = o3d.utility.Vector3dVector(np.zeros((0, 3)))
    started = time.monotonic()
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=args.neighbors))
    estimated = time.monotonic()
    cloud.orient_normals_consistent_tangent_plane(args.neighbors)
    oriented = time.monotonic()
    o3d.io.write_point_cloud(str(args.out), cloud, write_ascii=False)
    print(json.dumps({"points": len(cloud.points), "normals_seconds": estimated - started,
                      "orientation_seconds": oriented - estimated,
                      "peak_rss_bytes": peak_rss_bytes()}))


def poisson(args):
    cloud = read_points(args.oriented)
    started = time.monotonic()
    mesh, densities = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(
        cloud, depth=args.depth)
    solved = time.monotonic()
    o3d.io.write_triangle_mesh(f"{args.out}.ply", mesh, write_ascii=False)
    densities = np.asarray(densities)
    mesh.remove_vertices_by_mask(densities < np.quantile(densities, args.trim))
    trimmed = time.monotonic()
    o3d.io.write_triangle_mesh(f"{args.out}-trimmed.ply", mesh, write_ascii=False)
    print(json.dumps({"depth": args.depth, "poisson_seconds": solved - started,
                      "trim_seconds": trimmed - solved, "triangles": len(mesh.triangles),
                      "peak_rss_bytes": peak_rss_bytes()}))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    steps = parser.add_subparsers(dest="step", required=True)
    n = steps.add_parser("normals", help="estimate and orient normals")
    n.add_argument("scan")
    n.add_argument("out")
    n.add_argument("--neighbors", type=int, default=10)
    p = steps.add_parser("poisson", help="screened Poisson reconstruction")
    p.add_argument("oriented")
    p.add_argument("out")
    p.add_argument("--depth", type=int, required=True)
    p.add_argument("--trim", type=float, default=0.01)
    args = parser.parse_args()
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    normals(args) if args.step == "normals" else poisson(args)


if __name__ == "__main__":
    main()
