#include "pipeline/convert/checkpoints.h"

#include <string>

#include "pipeline/points/knn.h"

namespace iso {
namespace {

template <typename Load>
std::optional<std::invoke_result_t<Load, CheckpointReader&>> loadFrom(ResumeState& state,
                                                                      const std::string& name,
                                                                      Load&& load) {
  const std::unique_ptr<CheckpointReader> reader = state.open(name);
  if (!reader) return std::nullopt;
  try {
    auto loaded = load(*reader);
    reader->finish();
    return loaded;
  } catch (const CheckpointError& e) {
    state.discard(name, e.what());
  } catch (const nlohmann::json::exception& e) {
    state.discard(name, state.path(name).string() + ": " + e.what());
  }
  return std::nullopt;
}

}  // namespace

void savePoints(const ResumeState& state, const ReadyPoints& ready) {
  const std::unique_ptr<CheckpointWriter> out = state.create(kPointsCheckpoint);
  out->json("meta",
            {{"frame", {ready.frame.origin, ready.frame.size}},
             {"spacing", ready.radii.spacing},
             {"median_radius", ready.radii.medianRadius},
             {"normals", {ready.normals.estimated, ready.normals.flipped}},
             {"duplicates", ready.duplicates},
             {"outliers", {ready.outliers.removed, ready.outliers.sparse, ready.outliers.grouped}},
             {"out_of_core", ready.outOfCore},
             {"stray_extras", ready.strays.extraNames}});
  writeColumns(*out, ready.points);
  out->array("sample", ready.sample);
  out->array("strays.positions", ready.strays.positions);
  out->array("strays.normals", ready.strays.normals);
  out->array("strays.colors", ready.strays.colors);
  out->array("strays.extras", ready.strays.extras);
  out->commit();
}

std::optional<ReadyPoints> loadPoints(ResumeState& state) {
  return loadFrom(state, kPointsCheckpoint, [](CheckpointReader& in) {
    ReadyPoints ready;
    const nlohmann::json meta = in.json("meta");
    ready.frame.origin = meta["frame"][0].get<std::array<double, 3>>();
    ready.frame.size = meta["frame"][1];
    ready.radii.spacing = meta["spacing"];
    ready.radii.medianRadius = meta["median_radius"];
    ready.normals.estimated = meta["normals"][0];
    ready.normals.flipped = meta["normals"][1];
    ready.duplicates = meta["duplicates"];
    ready.outliers.removed = meta["outliers"][0];
    ready.outliers.sparse = meta["outliers"][1];
    ready.outliers.grouped = meta["outliers"][2];
    ready.outOfCore = meta["out_of_core"];
    ready.strays.extraNames = meta["stray_extras"].get<std::vector<std::string>>();
    readColumns(in, ready.points);
    in.array("sample", ready.sample);
    in.array("strays.positions", ready.strays.positions);
    in.array("strays.normals", ready.strays.normals);
    in.array("strays.colors", ready.strays.colors);
    in.array("strays.extras", ready.strays.extras);
    return ready;
  });
}

void saveCornerStage(const ResumeState& state, const CornerStageResults& r,
                     const std::string& name) {
  const std::unique_ptr<CheckpointWriter> out = state.create(name);
  const Closure& c = r.closure;
  out->json(
      "counts",
      {{"stats", {r.stats.testedPatches, r.stats.tooFar, r.stats.uncovered, r.stats.thinSplits}},
       {"passive", r.passive},
       {"splits", r.splits},
       {"trimmed", r.trimmed},
       {"closure", {c.cornersInUse, c.filled, c.refilled, c.passes}}});
  out->array("nodes", r.octree.nodes);
  out->array("corner.keys", c.corners.index.keys());
  out->array("corner.levels", c.corners.coarsestLevel);
  out->array("corner.values", c.corners.value);
  out->array("hanging", c.hanging);
  out->array("lod", r.lod);
  out->commit();
}

std::optional<CornerStageResults> loadCornerStage(ResumeState& state, const std::string& name) {
  return loadFrom(state, name, [&state, &name](CheckpointReader& in) {
    CornerStageResults r;
    const nlohmann::json counts = in.json("counts");
    r.stats = {counts["stats"][0], counts["stats"][1], counts["stats"][2], counts["stats"][3]};
    r.passive = counts["passive"];
    r.splits = counts["splits"];
    r.trimmed = counts["trimmed"];
    Closure& c = r.closure;
    c.cornersInUse = counts["closure"][0];
    c.filled = counts["closure"][1];
    c.refilled = counts["closure"][2];
    c.passes = counts["closure"][3];
    in.array("nodes", r.octree.nodes);
    UninitializedSpillVector<Key128> keys;
    in.array("corner.keys", keys);
    c.corners = CornerField(keys.size(), keys.size());
    for (const Key128& key : keys) c.corners.index.insert(key);  // numbered as they were
    keys = {};
    in.array("corner.levels", c.corners.coarsestLevel);
    in.array("corner.values", c.corners.value);
    if (c.corners.coarsestLevel.size() != c.corners.size() ||
        c.corners.value.size() != c.corners.size())
      throw CheckpointError(state.path(name).string() +
                            ": the corner field's arrays differ in length");
    in.array("hanging", c.hanging);
    in.array("lod", r.lod);
    return r;
  });
}

}  // namespace iso
