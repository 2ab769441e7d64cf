// VoxelMap: the attribute octree (CompactOctree), its column index and a reader/writer lock.
// Insertion computes rays without the lock (on several threads) and takes it only to apply
// the de-duplicated updates in key order; readers share the lock.
#pragma once

#include <memory>
#include <mutex>
#include <shared_mutex>

#include <Eigen/Core>
#include <octomap/OcTree.h>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "column_index.hpp"
#include "rw_lock.hpp"
#include "compact_octree.hpp"

namespace layerpilot {

class FlatKeyIndex;

using Points = Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor>;
using Colors = Eigen::Matrix<uint8_t, Eigen::Dynamic, 3, Eigen::RowMajor>;
using Queries = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;

struct SensorModel {
  double prob_hit = 0.7;
  double prob_miss = 0.4;
  double clamp_min = 0.1192;
  double clamp_max = 0.971;
  double occupied_threshold = 0.5;
};

struct InsertResult {
  size_t points_used = 0;
  size_t points_dropped = 0;  // NaN/inf or outside the map's key range
  size_t voxels_updated = 0;  // distinct voxels touched (free + occupied)
  size_t voxels_occupied = 0;  // of which endpoint (hit) voxels
};

// Column window: all arrays are row-major (height, width), row = y.
struct ColumnWindow {
  int64_t key_x0 = 0, key_y0 = 0;
  int width = 0, height = 0;
  std::vector<uint8_t> observed;
  std::vector<float> elevation;
  std::vector<uint8_t> color;  // (h, w, 3)
  std::vector<double> last_seen;
  std::vector<float> min_distance;
};

struct VoxelSet {
  std::vector<float> centers;  // (n, 3)
  std::vector<float> occupancy;
  std::vector<uint8_t> color;  // (n, 3)
  std::vector<double> last_seen;
  std::vector<float> min_distance;
  size_t size() const { return occupancy.size(); }
};

// A map stream that is not one complete, well-formed OctoMap file; the message says what is wrong
// and at which byte, so a damaged file is reported, never half-loaded.
struct MapFileError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

enum class FileFormat { Ot, Bt };

struct MapStats {
  double resolution;
  size_t nodes, leaves, node_bytes, occupied_leaves, attribute_records;
  // Whole map in memory: tree (groups, attribute records, free lists) + column index. Beside it,
  // the largest working memory one insert() has needed so far (bit grids, keys, endpoints).
  size_t tree_bytes, column_index_bytes, total_bytes, insert_scratch_bytes;
  double min[3], max[3];  // metric bounds of known space (0 if empty)
};

class VoxelMap {
 public:
  VoxelMap(double resolution, const SensorModel& model);

  // points in the map frame; colors: one row per point, or no rows for a frame without color.
  InsertResult insert(const Eigen::Ref<const Points>& points, const Eigen::Ref<const Colors>& colors,
                      const Eigen::Vector3d& origin, double stamp, double max_range);

  ColumnWindow columnLayers(int64_t key_x0, int64_t key_y0, int width, int height) const;
  Eigen::VectorXf occupancy(const Eigen::Ref<const Queries>& points) const;  // probability, NaN = unknown
  std::optional<Eigen::Vector3d> raycast(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                                         double max_range) const;
  VoxelSet voxels(const Eigen::Vector3d& box_min, const Eigen::Vector3d& box_max, double min_occupancy) const;

  // File I/O (voxel_map_io.cpp) works on whole streams in memory; Python writes and reads the files
  // (atomically, with an integrity footer). Ot: every attribute; Bt: occupancy, stock OcTree header.
  std::string serialize(FileFormat format) const;
  // Validates the whole stream (header, every node, exact end) before it builds anything; a stream
  // that fails throws MapFileError. Reads layerpilot's tree, stock OcTree/ColorOcTree .ot and .bt.
  static std::unique_ptr<VoxelMap> parse(const char* data, size_t size, const SensorModel& model);

  MapStats stats() const;
  double resolution() const { return geometry_.getResolution(); }
  const SensorModel& model() const { return model_; }
  // OctoMap's isNodeOccupied: log-odds >= the occupied threshold's. The one definition of
  // "occupied" (column index, raycast, .bt, stats, and the default of voxels()).
  bool occupied(const Node& n) const { return n.log_odds >= occupied_log_; }
  // Reader access to the tree, for the tests that compare it with OctoMap's (caller holds no other lock).
  template <class F>
  auto withTree(F&& f) const {
    std::shared_lock lock(mutex_);
    return f(tree_, geometry_);
  }

 private:
  struct Endpoint {
    octomap::OcTreeKey key;
    uint32_t rgb_sum[3] = {0, 0, 0};
    uint32_t count = 0;
    float min_distance = 0.f;
    bool hit = false;
  };
  struct RayBatch;  // per-frame scratch of insert()

  void applyModel();
  void applyUpdates(const std::vector<uint64_t>& codes, const std::vector<Endpoint>& endpoints,
                    const FlatKeyIndex& endpoint_index, bool have_color, float stamp);
  void updateLeaf(Node* node, bool created, const octomap::OcTreeKey& key, bool hit,
                  const Endpoint* ep, bool have_color, float stamp);
  bool cannotChange(float log_odds, bool hit) const;
  void finalizeInner(Node* node);
  void rebuildColumnIndex();

  SensorModel model_;
  // Key arithmetic and the sensor model's log-odds, exactly OctoMap's; holds no nodes.
  octomap::OcTree geometry_;
  CompactOctree tree_;
  size_t insert_scratch_bytes_ = 0;
  ColumnIndex columns_;
  float occupied_log_;
  mutable WriterPreferringLock mutex_;
};

}  // namespace layerpilot
