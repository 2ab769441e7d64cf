#include "voxel_map.hpp"

#include <octomap/OcTree.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <thread>
#include <cstdlib>

#include "keys.hpp"

namespace layerpilot {
namespace {

using octomap::OcTreeKey;
using octomap::point3d;

unsigned workerCount(size_t items) {
  static const unsigned hw = [] {
    const char* env = std::getenv("LAYERPILOT_THREADS");  // cap for shared machines and benchmarks
    const unsigned n = env ? static_cast<unsigned>(std::atoi(env)) : std::thread::hardware_concurrency();
    return std::max(1u, n);
  }();
  return items < 4096 ? 1u : std::min(hw, 8u);
}

// Runs f(worker, begin, end) over [0, n) split into one contiguous chunk per worker.
template <class F>
void parallelChunks(size_t n, unsigned workers, F&& f) {
  std::vector<std::thread> threads;
  for (unsigned w = 1; w < workers; ++w)
    threads.emplace_back([&, w] { f(w, n * w / workers, n * (w + 1) / workers); });
  f(0u, size_t(0), n / workers);
  for (auto& t : threads) t.join();
}

// OctoMap's computeRayKeys (Amanatides & Woo) with the same float/double arithmetic, so the keys
// match OctoMap's exactly, but with the state in registers and keys emitted to a sink.
template <class Sink>
bool walkRay(const octomap::OcTree& tree, const point3d& origin, const point3d& end, Sink&& sink) {
  OcTreeKey key_origin, key_end;
  if (!tree.coordToKeyChecked(origin, key_origin) || !tree.coordToKeyChecked(end, key_end)) return false;
  if (key_origin == key_end) return true;
  sink(key_origin[0], key_origin[1], key_origin[2]);
  point3d direction = end - origin;
  const float length = static_cast<float>(direction.norm());
  direction /= length;
  const double res = tree.getResolution();
  int step[3];
  double t_max[3], t_delta[3];
  for (unsigned i = 0; i < 3; ++i) {
    step[i] = direction(i) > 0.0 ? 1 : (direction(i) < 0.0 ? -1 : 0);
    if (step[i] != 0) {
      double border = tree.keyToCoord(key_origin[i]);
      border += static_cast<float>(step[i] * res * 0.5);
      t_max[i] = (border - origin(i)) / direction(i);
      t_delta[i] = res / std::fabs(direction(i));
    } else {
      t_max[i] = t_delta[i] = std::numeric_limits<double>::max();
    }
  }
  uint16_t x = key_origin[0], y = key_origin[1], z = key_origin[2];
  double tx = t_max[0], ty = t_max[1], tz = t_max[2];
  while (true) {
    if (tx < ty) {
      if (tx < tz) {
        x += step[0];
        tx += t_delta[0];
      } else {
        z += step[2];
        tz += t_delta[2];
      }
    } else if (ty < tz) {
      y += step[1];
      ty += t_delta[1];
    } else {
      z += step[2];
      tz += t_delta[2];
    }
    if (x == key_end[0] && y == key_end[1] && z == key_end[2]) return true;
    if (std::min(std::min(tx, ty), tz) > length) return true;
    sink(x, y, z);
  }
}

inline unsigned childAt(uint64_t code, unsigned depth) { return (code >> (3 * (15 - depth))) & 7; }

}  // namespace

VoxelMap::VoxelMap(double resolution, const SensorModel& model)
    : model_(model), geometry_(resolution > 0 ? resolution : 1.0) {
  if (!(resolution > 0)) throw std::invalid_argument("resolution must be > 0");
  geometry_.clearKeyRays();  // OctoMap's 600 kB ray buffer: insertion walks rays itself
  applyModel();
}

void VoxelMap::applyModel() {
  auto check = [](double p, const char* name) {
    if (!(p > 0.0 && p < 1.0)) throw std::invalid_argument(std::string(name) + " must be in (0, 1)");
  };
  check(model_.prob_hit, "prob_hit");
  check(model_.prob_miss, "prob_miss");
  check(model_.clamp_min, "clamp_min");
  check(model_.clamp_max, "clamp_max");
  check(model_.occupied_threshold, "occupied_threshold");
  if (model_.prob_hit <= 0.5) throw std::invalid_argument("prob_hit must be > 0.5");
  if (model_.prob_miss >= 0.5) throw std::invalid_argument("prob_miss must be < 0.5");
  if (model_.clamp_min >= model_.clamp_max) throw std::invalid_argument("clamp_min must be < clamp_max");
  geometry_.setProbHit(model_.prob_hit);
  geometry_.setProbMiss(model_.prob_miss);
  geometry_.setClampingThresMin(model_.clamp_min);
  geometry_.setClampingThresMax(model_.clamp_max);
  geometry_.setOccupancyThres(model_.occupied_threshold);
  occupied_log_ = geometry_.getOccupancyThresLog();
}

InsertResult VoxelMap::insert(const Eigen::Ref<const Points>& cloud, const Eigen::Ref<const Colors>& colors,
                              const Eigen::Vector3d& origin_d, double stamp, double max_range) {
  if (colors.rows() != 0 && colors.rows() != cloud.rows())
    throw std::invalid_argument("colors must have one row per point");
  InsertResult result;
  const size_t n = cloud.rows();
  const float* points = cloud.data();
  const uint8_t* rgb = colors.rows() ? colors.data() : nullptr;
  const point3d origin(static_cast<float>(origin_d.x()), static_cast<float>(origin_d.y()),
                       static_cast<float>(origin_d.z()));
  OcTreeKey origin_key;
  if (!geometry_.coordToKeyChecked(origin, origin_key)) throw std::invalid_argument("origin is outside the map");

  // 1. Collapse endpoints per voxel (one accumulator per distinct key), on every core.
  const unsigned workers = workerCount(n);
  std::vector<std::vector<Endpoint>> endpoints(workers);
  std::vector<FlatKeyIndex> indices;
  for (unsigned w = 0; w < workers; ++w) indices.emplace_back(1024);
  std::vector<size_t> dropped(workers, 0);
  parallelChunks(n, workers, [&](unsigned w, size_t begin, size_t end) {
    auto& eps = endpoints[w];
    auto& index = indices[w];
    uint64_t last_key = ~0ULL;
    uint32_t last_index = 0;
    for (size_t i = begin; i < end; ++i) {
      const float* p = points + 3 * i;
      OcTreeKey key;
      if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]) ||
          !geometry_.coordToKeyChecked(point3d(p[0], p[1], p[2]), key)) {
        ++dropped[w];
        continue;
      }
      const uint64_t packed = packKey(key);
      if (packed != last_key) {
        auto [idx, inserted] = index.insert(packed, static_cast<uint32_t>(eps.size()));
        if (inserted) {
          eps.emplace_back();
          eps.back().key = key;
          eps.back().min_distance = std::numeric_limits<float>::infinity();
        }
        last_key = packed;
        last_index = idx;
      }
      Endpoint& e = eps[last_index];
      const float dx = p[0] - origin.x(), dy = p[1] - origin.y(), dz = p[2] - origin.z();
      e.min_distance = std::min(e.min_distance, std::sqrt(dx * dx + dy * dy + dz * dz));
      if (rgb) {
        for (int c = 0; c < 3; ++c) e.rgb_sum[c] += rgb[3 * i + c];
      }
      ++e.count;
    }
  });
  for (size_t d : dropped) result.points_dropped += d;
  result.points_used = n - result.points_dropped;
  std::vector<Endpoint>& merged = endpoints[0];
  FlatKeyIndex& merged_index = indices[0];
  for (unsigned w = 1; w < workers; ++w) {
    for (const Endpoint& e : endpoints[w]) {
      auto [idx, inserted] = merged_index.insert(packKey(e.key), static_cast<uint32_t>(merged.size()));
      if (inserted) {
        merged.push_back(e);
        continue;
      }
      Endpoint& m = merged[idx];
      for (int c = 0; c < 3; ++c) m.rgb_sum[c] += e.rgb_sum[c];
      m.count += e.count;
      m.min_distance = std::min(m.min_distance, e.min_distance);
    }
  }

  // 2. Cast one ray per endpoint voxel centre (OctoMap's discretized insertion), marking free
  //    cells in a per-worker sparse bit grid so each free voxel is collected once.
  const unsigned ray_workers = workerCount(merged.size() * 16);
  std::vector<SparseBitGrid> grids(ray_workers);
  std::vector<std::vector<uint64_t>> free_codes(ray_workers);
  parallelChunks(merged.size(), ray_workers, [&](unsigned w, size_t begin, size_t end) {
    auto& grid = grids[w];
    auto& out = free_codes[w];
    auto sink = [&](uint16_t x, uint16_t y, uint16_t z) {
      if (grid.testAndSet(x, y, z)) out.push_back(morton(OcTreeKey(x, y, z)) << 1);
    };
    for (size_t i = begin; i < end; ++i) {
      Endpoint& e = merged[i];
      const point3d centre = geometry_.keyToCoord(e.key);
      if (max_range < 0.0 || (centre - origin).norm() <= max_range) {
        walkRay(geometry_, origin, centre, sink);
        e.hit = true;
      } else {
        const point3d dir = (centre - origin).normalized();
        walkRay(geometry_, origin, origin + dir * static_cast<float>(max_range), sink);
      }
    }
  });
  std::vector<uint64_t> codes = std::move(free_codes[0]);
  for (unsigned w = 1; w < ray_workers; ++w)
    for (uint64_t c : free_codes[w])
      if (!grids[0].contains(unmorton(c >> 1))) codes.push_back(c);
  for (const Endpoint& e : merged)
    if (e.hit) codes.push_back((morton(e.key) << 1) | 1);

  // 3. Key order = OctoMap's depth-first order; a hit wins over a miss of the same voxel.
  uint64_t varying = 0;  // only the bits that differ between codes need sorting
  for (uint64_t c : codes) varying |= c ^ codes.front();
  radixSort(codes, varying ? 64 - __builtin_clzll(varying) : 0);
  size_t unique = 0;
  for (size_t i = 0; i < codes.size(); ++i) {
    if (unique > 0 && (codes[unique - 1] >> 1) == (codes[i] >> 1))
      codes[unique - 1] = codes[i];  // sorted: the hit (low bit 1) comes last
    else
      codes[unique++] = codes[i];
  }
  codes.resize(unique);
  for (uint64_t c : codes) result.voxels_occupied += c & 1;
  result.voxels_updated = unique;

  size_t scratch = 2 * codes.capacity() * sizeof(uint64_t) + (1 << 16) * sizeof(uint32_t);  // + radix sort's
  for (unsigned w = 0; w < workers; ++w) scratch += endpoints[w].capacity() * sizeof(Endpoint) + indices[w].memoryBytes();
  for (unsigned w = 0; w < ray_workers; ++w) scratch += grids[w].memoryBytes();

  std::unique_lock lock(mutex_);
  insert_scratch_bytes_ = std::max(insert_scratch_bytes_, scratch);
  applyUpdates(codes, merged, merged_index, rgb != nullptr, static_cast<float>(stamp));
  return result;
}

// Applies sorted updates with one descent per key that reuses the path shared with the previous
// key; inner nodes are pruned or refreshed once, when the walk leaves them.
void VoxelMap::applyUpdates(const std::vector<uint64_t>& codes, const std::vector<Endpoint>& endpoints,
                            const FlatKeyIndex& endpoint_index, bool have_color, float stamp) {
  if (codes.empty()) return;
  constexpr unsigned kDepth = CompactOctree::kDepth;
  const bool root_created = tree_.empty();
  Node* path[kDepth + 1];
  path[0] = root_created ? tree_.createRoot() : tree_.root();
  unsigned last = 0;  // depth of the deepest valid node on the path
  uint64_t prev = 0;
  bool first = true;
  for (uint64_t entry : codes) {
    const uint64_t code = entry >> 1;
    const bool hit = entry & 1;
    unsigned start = 0;
    // Only the root can be a fresh node without children at the start of a descent; any other
    // childless node on the path is a pruned leaf.
    bool created = first && root_created;
    if (!first) {
      const unsigned diff_level = (63 - __builtin_clzll(prev ^ code)) / 3;
      start = std::min(kDepth - 1 - diff_level, last);
      for (unsigned d = last; d-- > start + 1;) finalizeInner(path[d]);
    }
    prev = code;
    first = false;
    Node* node = path[start];
    unsigned depth = start;
    bool skipped = false;
    for (; depth < kDepth; ++depth) {
      const unsigned pos = childAt(code, depth);
      Node* next = tree_.child(*node, pos);
      if (!next) {
        if (!CompactOctree::hasChildren(*node) && !created) {
          // A pruned leaf: OctoMap skips updates that cannot change it, else expands it. A hit
          // always expands it: the voxel's own color, time and distance change.
          if (!hit && cannotChange(node->log_odds, hit)) {
            skipped = true;
            break;
          }
          tree_.expand(*node);
          next = tree_.child(*node, pos);
          created = false;
        } else {
          next = tree_.createChild(*node, pos);
          created = true;
        }
      } else {
        created = false;
      }
      node = next;
      path[depth + 1] = node;
    }
    last = depth;
    if (skipped) continue;
    const OcTreeKey key = unmorton(code);
    const Endpoint* ep = nullptr;
    if (hit) ep = &endpoints[*endpoint_index.find(packKey(key))];
    updateLeaf(node, created, key, hit, ep, have_color, stamp);
  }
  for (unsigned d = last; d-- > 0;) finalizeInner(path[d]);
}

void VoxelMap::updateLeaf(Node* node, bool created, const OcTreeKey& key, bool hit, const Endpoint* ep,
                          bool have_color, float stamp) {
  const float v = node->log_odds;
  // OctoMap's early abort: at a clamping bound the log-odds stay; a hit still updates the attributes.
  const bool clamped = !created && cannotChange(v, hit);
  if (clamped && !hit) return;
  const bool was_occupied = !created && v >= occupied_log_;  // occupied() before the update
  if (!clamped) {  // OctoMap's updateNodeLogOdds: add, then clamp.
    float& l = node->log_odds;
    l += hit ? geometry_.getProbHitLog() : geometry_.getProbMissLog();
    if (l < geometry_.getClampingThresMinLog())
      l = geometry_.getClampingThresMinLog();
    else if (l > geometry_.getClampingThresMaxLog())
      l = geometry_.getClampingThresMaxLog();
  }
  const bool now_occupied = occupied(*node);
  if (hit) {
    Attributes& a = tree_.attributes(*node);
    a.last_seen = stamp;
    a.min_distance = std::min(a.min_distance, ep->min_distance);
    if (have_color)
      a.color = Rgb{static_cast<uint8_t>((ep->rgb_sum[0] + ep->count / 2) / ep->count),
                    static_cast<uint8_t>((ep->rgb_sum[1] + ep->count / 2) / ep->count),
                    static_cast<uint8_t>((ep->rgb_sum[2] + ep->count / 2) / ep->count)};
  }
  if (!now_occupied && !was_occupied) return;
  Column& column = columns_.at(key[0], key[1]);
  if (now_occupied && !was_occupied) {
    if (ColumnIndex::addOccupied(column, key[2])) column.setTopAttributes(tree_.attributesOf(*node));
  } else if (now_occupied) {
    if (hit && column.top == key[2]) column.setTopAttributes(tree_.attributesOf(*node));
  } else {
    auto leafAt = [&](uint16_t z) { return tree_.search(OcTreeKey(key[0], key[1], z)); };
    auto occupiedAt = [&](uint16_t z) {
      const Node* n = leafAt(z);
      return n && occupied(*n);
    };
    if (ColumnIndex::removeOccupied(column, key[2], occupiedAt) && column.occupied > 0)
      column.setTopAttributes(tree_.attributesOf(*leafAt(column.top)));
  }
}

bool VoxelMap::cannotChange(float log_odds, bool hit) const {
  return hit ? log_odds >= geometry_.getClampingThresMaxLog() : log_odds <= geometry_.getClampingThresMinLog();
}

void VoxelMap::finalizeInner(Node* node) {
  if (!tree_.prune(*node)) tree_.updateFromChildren(*node);
}

void VoxelMap::rebuildColumnIndex() {
  columns_.clear();
  tree_.forEachLeaf([&](const Node& leaf, const OcTreeKey& base, unsigned depth) {
    if (!occupied(leaf)) return;
    const unsigned span = 1u << (CompactOctree::kDepth - depth);  // at most 256 (voxel_map_io.cpp)
    for (unsigned dx = 0; dx < span; ++dx)
      for (unsigned dy = 0; dy < span; ++dy) {
        Column& c = columns_.at(base[0] + dx, base[1] + dy);
        if (ColumnIndex::addOccupied(c, base[2] + span - 1, span)) c.setTopAttributes(tree_.attributesOf(leaf));
      }
  });
}

ColumnWindow VoxelMap::columnLayers(int64_t key_x0, int64_t key_y0, int width, int height) const {
  if (width <= 0 || height <= 0) throw std::invalid_argument("width and height must be > 0");
  ColumnWindow w;
  w.key_x0 = key_x0;
  w.key_y0 = key_y0;
  w.width = width;
  w.height = height;
  const size_t cells = size_t(width) * height;
  w.observed.assign(cells, 0);
  w.elevation.assign(cells, std::numeric_limits<float>::quiet_NaN());
  w.color.assign(cells * 3, 0);
  w.last_seen.assign(cells, std::numeric_limits<double>::quiet_NaN());
  w.min_distance.assign(cells, std::numeric_limits<float>::infinity());
  const double res = geometry_.getResolution();
  std::shared_lock lock(mutex_);
  columns_.forEachShowing(key_x0, key_y0, width, height, [&](int64_t kx, int64_t ky, const Column& c) {
    const size_t i = size_t(ky - key_y0) * width + size_t(kx - key_x0);
    w.observed[i] = 1;
    w.elevation[i] = static_cast<float>(geometry_.keyToCoord(c.top) + 0.5 * res);
    w.color[3 * i] = c.color.r;
    w.color[3 * i + 1] = c.color.g;
    w.color[3 * i + 2] = c.color.b;
    w.last_seen[i] = c.last_seen;
    w.min_distance[i] = c.min_distance;
  });
  return w;
}

Eigen::VectorXf VoxelMap::occupancy(const Eigen::Ref<const Queries>& points) const {
  Eigen::VectorXf out = Eigen::VectorXf::Constant(points.rows(), std::numeric_limits<float>::quiet_NaN());
  std::shared_lock lock(mutex_);
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    OcTreeKey key;
    if (!points.row(i).allFinite() || !geometry_.coordToKeyChecked(points(i, 0), points(i, 1), points(i, 2), key))
      continue;
    if (const Node* node = tree_.search(key)) out[i] = static_cast<float>(octomap::probability(node->log_odds));
  }
  return out;
}

// OctoMap's castRay (ignoring unknown cells), on the compact tree.
std::optional<Eigen::Vector3d> VoxelMap::raycast(const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                                                 double max_range) const {
  std::shared_lock lock(mutex_);
  const point3d origin(o.x(), o.y(), o.z());
  OcTreeKey key;
  if (tree_.empty() || !geometry_.coordToKeyChecked(origin, key)) return std::nullopt;
  auto occupiedAt = [&](const OcTreeKey& k) {
    const Node* n = tree_.search(k);
    return n && occupied(*n);
  };
  auto hit = [&](const OcTreeKey& k) {
    const point3d c = geometry_.keyToCoord(k);
    return Eigen::Vector3d(c.x(), c.y(), c.z());
  };
  if (occupiedAt(key)) return hit(key);
  const point3d direction = point3d(d.x(), d.y(), d.z()).normalized();
  const double res = geometry_.getResolution();
  int step[3];
  double t_max[3], t_delta[3];
  for (unsigned i = 0; i < 3; ++i) {
    step[i] = direction(i) > 0.0 ? 1 : (direction(i) < 0.0 ? -1 : 0);
    if (step[i] != 0) {
      const double border = geometry_.keyToCoord(key[i]) + double(step[i] * res * 0.5);
      t_max[i] = (border - origin(i)) / direction(i);
      t_delta[i] = res / std::fabs(direction(i));
    } else {
      t_max[i] = t_delta[i] = std::numeric_limits<double>::max();
    }
  }
  if (step[0] == 0 && step[1] == 0 && step[2] == 0) return std::nullopt;
  const double max_range_sq = max_range * max_range;
  const unsigned max_key = 2 * 32768 - 1;
  while (true) {
    const unsigned dim = t_max[0] < t_max[1] ? (t_max[0] < t_max[2] ? 0 : 2) : (t_max[1] < t_max[2] ? 1 : 2);
    if ((step[dim] < 0 && key[dim] == 0) || (step[dim] > 0 && key[dim] == max_key)) return std::nullopt;
    key[dim] += step[dim];
    t_max[dim] += t_delta[dim];
    if (max_range > 0.0) {
      const point3d end = geometry_.keyToCoord(key);
      double dist_sq = 0.0;
      for (unsigned j = 0; j < 3; ++j) dist_sq += (end(j) - origin(j)) * (end(j) - origin(j));
      if (dist_sq > max_range_sq) return std::nullopt;
    }
    if (occupiedAt(key)) return hit(key);
  }
}

VoxelSet VoxelMap::voxels(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, double min_occupancy) const {
  VoxelSet out;
  std::shared_lock lock(mutex_);
  OcTreeKey key_lo, key_hi;
  if (tree_.empty()) return out;
  const point3d plo(lo.x(), lo.y(), lo.z()), phi(hi.x(), hi.y(), hi.z());
  if (!geometry_.coordToKeyChecked(plo, key_lo) || !geometry_.coordToKeyChecked(phi, key_hi))
    throw std::invalid_argument("box is outside the map's key range");
  const float min_log = static_cast<float>(octomap::logodds(min_occupancy));
  auto overlaps = [&](const OcTreeKey& base, unsigned depth) {  // the node's key cube meets the box's
    const unsigned span = 1u << (CompactOctree::kDepth - depth);
    for (int a = 0; a < 3; ++a)
      if (base[a] + span - 1 < key_lo[a] || base[a] > key_hi[a]) return false;
    return true;
  };
  tree_.forEachLeaf(overlaps, [&](const Node& leaf, const OcTreeKey& base, unsigned depth) {
    if (leaf.log_odds < min_log) return;
    const Attributes& attr = tree_.attributesOf(leaf);
    const float occupancy = static_cast<float>(octomap::probability(leaf.log_odds));
    const unsigned span = 1u << (CompactOctree::kDepth - depth);
    for (unsigned dx = 0; dx < span; ++dx)
      for (unsigned dy = 0; dy < span; ++dy)
        for (unsigned dz = 0; dz < span; ++dz) {
          const OcTreeKey k(base[0] + dx, base[1] + dy, base[2] + dz);
          const double c[3] = {geometry_.keyToCoord(k[0]), geometry_.keyToCoord(k[1]), geometry_.keyToCoord(k[2])};
          bool inside = true;  // voxels whose centre lies in the box
          for (int a = 0; a < 3; ++a) inside = inside && c[a] >= lo[a] && c[a] <= hi[a];
          if (!inside) continue;
          for (int a = 0; a < 3; ++a) out.centers.push_back(static_cast<float>(c[a]));
          out.occupancy.push_back(occupancy);
          out.color.insert(out.color.end(), {attr.color.r, attr.color.g, attr.color.b});
          out.last_seen.push_back(attr.last_seen);
          out.min_distance.push_back(attr.min_distance);
        }
  });
  return out;
}

MapStats VoxelMap::stats() const {
  std::shared_lock lock(mutex_);
  MapStats s{};
  s.resolution = geometry_.getResolution();
  s.nodes = tree_.nodeCount();
  s.leaves = tree_.leafCount();
  s.node_bytes = sizeof(Node);
  s.attribute_records = tree_.attributeRecords();
  s.tree_bytes = tree_.memoryBytes() + sizeof(geometry_);
  s.column_index_bytes = columns_.memoryBytes();
  s.insert_scratch_bytes = insert_scratch_bytes_;
  s.total_bytes = s.tree_bytes + s.column_index_bytes;
  double lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    lo[a] = std::numeric_limits<double>::max();
    hi[a] = -std::numeric_limits<double>::max();
  }
  tree_.forEachLeaf([&](const Node& leaf, const OcTreeKey& base, unsigned depth) {
    s.occupied_leaves += occupied(leaf);
    const double size = geometry_.getNodeSize(depth);  // OctoMap's calcMinMax
    for (int a = 0; a < 3; ++a) {
      const double low = geometry_.keyToCoord(base[a], depth) - size / 2.0;
      lo[a] = std::min(lo[a], low);
      hi[a] = std::max(hi[a], low + size);
    }
  });
  if (!tree_.empty())
    for (int a = 0; a < 3; ++a) {
      s.min[a] = lo[a];
      s.max[a] = hi[a];
    }
  return s;
}

}  // namespace layerpilot
