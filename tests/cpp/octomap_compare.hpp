// What the C++ tests share: every node of a tree (layerpilot's or OctoMap's) as a flat list in
// depth-first order, an exact comparison of two such lists, random clouds and the real scan.
#pragma once

#include <bzlib.h>
#include <gtest/gtest.h>
#include <octomap/OcTree.h>

#include <algorithm>
#include <cstdio>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "voxel_map.hpp"

namespace layerpilot::test {

// One node: its lowest-corner key, depth, log-odds, whether it has children, and (leaves) attributes.
struct NodeRecord {
  uint16_t key[3];
  unsigned depth;
  float log_odds;
  bool inner;
  Attributes attributes;
  bool operator==(const NodeRecord& o) const {
    return key[0] == o.key[0] && key[1] == o.key[1] && key[2] == o.key[2] && depth == o.depth &&
           log_odds == o.log_odds && inner == o.inner && attributes == o.attributes;
  }
};

// Stock OctoMap nodes have no attributes (reference_tree.hpp adds the overload for its node).
inline Attributes attributesOfNode(const octomap::OcTreeNode&) { return Attributes{}; }

inline std::string describe(const NodeRecord& n) {
  std::ostringstream s;
  s.precision(9);
  const Attributes& a = n.attributes;
  s << "key (" << n.key[0] << ", " << n.key[1] << ", " << n.key[2] << ") depth " << n.depth << " log-odds "
    << n.log_odds << (n.inner ? " inner" : " leaf") << " rgb " << int(a.color.r) << "," << int(a.color.g) << ","
    << int(a.color.b) << " last seen " << a.last_seen << " min distance " << a.min_distance;
  return s.str();
}

// children(node, i) -> child or nullptr; inner(node); log_odds(node); attributes(node).
template <class NodeT, class Children, class Inner, class LogOdds, class Attrs>
void collect(const NodeT* n, octomap::OcTreeKey key, unsigned depth, Children&& children, Inner&& inner,
             LogOdds&& log_odds, Attrs&& attributes, std::vector<NodeRecord>& out) {
  const bool has_children = inner(n);
  out.push_back({{key[0], key[1], key[2]}, depth, log_odds(n), has_children,
                 has_children ? Attributes{} : attributes(n)});
  if (!has_children) return;
  const uint16_t half = static_cast<uint16_t>(1u << (15 - depth));
  for (unsigned i = 0; i < 8; ++i)
    if (const NodeT* c = children(n, i)) {
      const octomap::OcTreeKey k(key[0] + ((i & 1) ? half : 0), key[1] + ((i & 2) ? half : 0),
                                 key[2] + ((i & 4) ? half : 0));
      collect(c, k, depth + 1, children, inner, log_odds, attributes, out);
    }
}

inline std::vector<NodeRecord> nodesOf(const VoxelMap& map) {
  std::vector<NodeRecord> out;
  map.withTree([&](const CompactOctree& t, const octomap::OcTree&) {
    if (const Node* root = t.root())
      collect(
          root, octomap::OcTreeKey(0, 0, 0), 0, [&](const Node* n, unsigned i) { return t.child(*n, i); },
          [](const Node* n) { return CompactOctree::hasChildren(*n); }, [](const Node* n) { return n->log_odds; },
          [&](const Node* n) { return t.attributesOf(*n); }, out);
    return 0;
  });
  return out;
}

template <class Tree>
std::vector<NodeRecord> nodesOf(const Tree& tree) {
  using NodeT = typename Tree::NodeType;
  std::vector<NodeRecord> out;
  if (const NodeT* root = tree.getRoot())
    collect(
        root, octomap::OcTreeKey(0, 0, 0), 0,
        [&](const NodeT* n, unsigned i) { return tree.nodeChildExists(n, i) ? tree.getNodeChild(n, i) : nullptr; },
        [&](const NodeT* n) { return tree.nodeHasChildren(n); }, [](const NodeT* n) { return n->getLogOdds(); },
        [](const NodeT* n) { return attributesOfNode(*n); }, out);
  return out;
}

// Exact equality, node for node (structure, so also pruning, and every log-odds bit for bit).
inline ::testing::AssertionResult sameNodes(const std::vector<NodeRecord>& a, const std::vector<NodeRecord>& b) {
  size_t differ = 0, first = std::min(a.size(), b.size());
  for (size_t i = 0; i < std::min(a.size(), b.size()); ++i)
    if (!(a[i] == b[i])) {
      first = std::min(first, i);
      ++differ;
    }
  if (differ == 0 && a.size() == b.size()) return ::testing::AssertionSuccess();
  auto result = ::testing::AssertionFailure() << a.size() << " against " << b.size() << " nodes, " << differ
                                              << " differ in the common prefix";
  if (first < std::min(a.size(), b.size()))
    result << "; first at node " << first << ": " << describe(a[first]) << " against " << describe(b[first]);
  return result;
}

// Every finest-level voxel a tree knows, as (key, log-odds) in key order: pruned leaves expanded,
// so trees that prune differently (layerpilot's keeps voxels apart whose attributes differ) compare.
struct VoxelRecord {
  uint64_t key;  // x | y << 16 | z << 32
  float log_odds;
  bool operator==(const VoxelRecord& o) const { return key == o.key && log_odds == o.log_odds; }
  bool operator<(const VoxelRecord& o) const { return key < o.key; }
};

inline std::vector<VoxelRecord> voxelsOf(const std::vector<NodeRecord>& nodes) {
  std::vector<VoxelRecord> out;
  for (const auto& n : nodes) {
    if (n.inner) continue;
    const unsigned span = 1u << (16 - n.depth);
    for (uint64_t dx = 0; dx < span; ++dx)
      for (uint64_t dy = 0; dy < span; ++dy)
        for (uint64_t dz = 0; dz < span; ++dz)
          out.push_back({(n.key[0] + dx) | ((n.key[1] + dy) << 16) | ((n.key[2] + dz) << 32), n.log_odds});
  }
  std::sort(out.begin(), out.end());
  return out;
}

inline ::testing::AssertionResult sameVoxels(const std::vector<VoxelRecord>& a, const std::vector<VoxelRecord>& b) {
  if (a == b) return ::testing::AssertionSuccess();
  size_t differ = 0;
  for (size_t i = 0; i < std::min(a.size(), b.size()); ++i) differ += !(a[i] == b[i]);
  return ::testing::AssertionFailure() << a.size() << " against " << b.size() << " voxels, " << differ
                                       << " differ in key or log-odds at the same position";
}

inline size_t leavesAbove(const std::vector<NodeRecord>& nodes, unsigned depth) {
  size_t n = 0;
  for (const auto& r : nodes) n += !r.inner && r.depth < depth;
  return n;
}

struct Cloud {
  Points points;
  octomap::Pointcloud octomap;
};

inline Cloud makeCloud(const std::vector<octomap::point3d>& pts) {
  Cloud c;
  c.points.resize(static_cast<Eigen::Index>(pts.size()), 3);
  for (size_t i = 0; i < pts.size(); ++i) {
    c.points.row(static_cast<Eigen::Index>(i)) << pts[i].x(), pts[i].y(), pts[i].z();
    c.octomap.push_back(pts[i]);
  }
  return c;
}

inline const Colors& noColors() {
  static const Colors none(0, 3);
  return none;
}

// OctoMap's sample scan (88206 points, origin at 0): the points of scan.dat.bz2.
inline std::vector<octomap::point3d> scanPoints() {
  const std::string path = std::string(LAYERPILOT_OCTOMAP_DATA) + "/scan.dat.bz2";
  FILE* file = std::fopen(path.c_str(), "rb");
  if (!file) throw std::runtime_error("reference data missing: " + path);
  int error = 0;
  BZFILE* bz = BZ2_bzReadOpen(&error, file, 0, 0, nullptr, 0);
  std::string text;
  char buffer[1 << 16];
  while (error == BZ_OK) {
    const int n = BZ2_bzRead(&error, bz, buffer, sizeof(buffer));
    if (n > 0) text.append(buffer, static_cast<size_t>(n));
  }
  BZ2_bzReadClose(&error, bz);
  std::fclose(file);
  std::istringstream lines(text);
  std::vector<octomap::point3d> out;
  float x, y, z;
  while (lines >> x >> y >> z) out.emplace_back(x, y, z);
  return out;
}

// A frame of a random scene: `n` endpoints in a box around the origin, on a few walls (so that
// voxels are hit again and again, reach the clamping bounds and prune) and scattered, some of them
// beyond `far` metres.
inline std::vector<octomap::point3d> randomFrame(std::mt19937& rng, size_t n, float far) {
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  std::vector<octomap::point3d> pts;
  for (size_t i = 0; i < n; ++i) {
    const float a = u(rng), b = u(rng), c = u(rng);
    switch (i % 4) {
      case 0: pts.emplace_back(0.4f * far, a * far, 0.5f * b * far); break;     // a wall
      case 1: pts.emplace_back(a * far, b * far, -0.25f * far); break;          // the ground
      case 2: pts.emplace_back(a * far, b * far, c * far); break;               // scattered
      default: pts.emplace_back(1.6f * a * far, 1.6f * b * far, 0.3f * far); break;  // some beyond range
    }
  }
  return pts;
}

}  // namespace layerpilot::test
