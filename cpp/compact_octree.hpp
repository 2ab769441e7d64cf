// The map's octree in memory: OctoMap's tree (same keys, log-odds, clamping and lossless pruning,
// so it agrees with OctoMap voxel for voxel and writes the same files), stored compactly.
//
// OctoMap spends 16 bytes per node plus a 64-byte array of child pointers per inner node. Here
// the 8 children of an inner node live together in one 64-byte group of 8-byte nodes (log-odds
// and a 32-bit link), so a child costs nothing beyond its group; groups and attribute records sit
// in chunks (stable addresses, never copied, at most one chunk's slack) with free lists. The attributes
// (color, last seen, min distance) exist only for voxels that were hit: a leaf links to its
// record, an inner node to its children. Unknown children are NaN log-odds.
#pragma once

#include <octomap/OcTreeKey.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

namespace layerpilot {

struct Rgb {
  uint8_t r = 0, g = 0, b = 0;
  bool operator==(const Rgb& o) const { return r == o.r && g == o.g && b == o.b; }
};

// What a voxel remembers beyond occupancy; the defaults are those of a voxel never hit.
struct Attributes {
  Rgb color;
  // Mission clock seconds (float32: ~1 ms resolution over a 2-hour mission); NaN = never hit.
  float last_seen = std::numeric_limits<float>::quiet_NaN();
  // Metres from the sensor origin, minimum over all hits; +inf = never hit.
  float min_distance = std::numeric_limits<float>::infinity();

  // As OctoMap's node equality for pruning: a voxel never loses its own color/time/distance.
  bool operator==(const Attributes& o) const {
    return color == o.color && (last_seen == o.last_seen || (std::isnan(last_seen) && std::isnan(o.last_seen))) &&
           min_distance == o.min_distance;
  }
};

struct Node {
  float log_odds = std::numeric_limits<float>::quiet_NaN();  // NaN: this child does not exist
  uint32_t link = 0;  // kInner | group of children; else attribute record + 1, 0 = none
};
static_assert(sizeof(Node) == 8);

// Chunks of T with a free list: addresses stay valid while the pool grows, and no chunk is ever
// copied. Chunk sizes ramp up from 64 to 2^kMaxBits items, so a small map wastes little.
template <class T, unsigned kMaxBits>
class ChunkPool {
 public:
  uint32_t allocate() {
    if (!free_.empty()) {
      const uint32_t i = free_.back();
      free_.pop_back();
      return i;
    }
    if (size_ == capacity_) {
      const uint32_t chunk = static_cast<uint32_t>(chunks_.size());
      const uint32_t items = chunk < kRampChunks ? kFirst << chunk : kMax;
      chunks_.emplace_back(new T[items]);
      capacity_ += items;
    }
    return size_++;
  }
  void release(uint32_t i) { free_.push_back(i); }
  T& operator[](uint32_t i) { return at(i); }
  const T& operator[](uint32_t i) const { return const_cast<ChunkPool*>(this)->at(i); }
  size_t live() const { return size_ - free_.size(); }
  size_t memoryBytes() const {
    return capacity_ * sizeof(T) + chunks_.capacity() * sizeof(std::unique_ptr<T[]>) +
           free_.capacity() * sizeof(uint32_t);
  }

 private:
  static constexpr unsigned kFirstBits = 6;
  static constexpr uint32_t kFirst = 1u << kFirstBits, kMax = 1u << kMaxBits;
  static constexpr uint32_t kRampChunks = kMaxBits - kFirstBits;  // 64, 128, ... up to kMax / 2
  static constexpr uint32_t kRamp = kMax - kFirst;                // items in the ramp chunks

  T& at(uint32_t i) {
    if (i < kRamp) {
      const uint32_t shifted = i + kFirst;
      const unsigned chunk = (31 - __builtin_clz(shifted)) - kFirstBits;
      return chunks_[chunk][shifted - (kFirst << chunk)];
    }
    const uint32_t j = i - kRamp;
    return chunks_[kRampChunks + (j >> kMaxBits)][j & (kMax - 1)];
  }

  std::vector<std::unique_ptr<T[]>> chunks_;
  std::vector<uint32_t> free_;
  uint32_t size_ = 0, capacity_ = 0;
};

class CompactOctree {
 public:
  static constexpr unsigned kDepth = 16;
  static constexpr uint32_t kInner = 0x80000000u;
  struct Group {
    Node child[8];
  };

  CompactOctree() = default;
  CompactOctree(const CompactOctree&) = delete;
  CompactOctree& operator=(const CompactOctree&) = delete;

  bool empty() const { return std::isnan(root_.log_odds); }
  Node* root() { return empty() ? nullptr : &root_; }
  const Node* root() const { return empty() ? nullptr : &root_; }
  Node* createRoot() {
    root_ = Node{0.f, 0};
    nodes_ = 1;
    return &root_;
  }

  static bool hasChildren(const Node& n) { return n.link & kInner; }
  Group& children(const Node& n) { return groups_[n.link & ~kInner]; }
  const Group& children(const Node& n) const { return groups_[n.link & ~kInner]; }
  // The child, or nullptr if it does not exist.
  Node* child(const Node& n, unsigned i) {
    if (!hasChildren(n)) return nullptr;
    Node& c = children(n).child[i];
    return std::isnan(c.log_odds) ? nullptr : &c;
  }
  const Node* child(const Node& n, unsigned i) const { return const_cast<CompactOctree*>(this)->child(n, i); }

  // A new child with log-odds 0 (OctoMap's new node); `n` has no attributes (never a hit leaf).
  Node* createChild(Node& n, unsigned i) {
    if (!hasChildren(n)) {
      dropAttributes(n);
      n.link = kInner | newGroup();
    }
    Node& c = children(n).child[i];
    c = Node{0.f, 0};
    ++nodes_;
    return &c;
  }

  // OctoMap's expandNode: eight children, each a copy of the pruned leaf (attributes included).
  void expand(Node& n) {
    const uint32_t g = newGroup();
    for (Node& c : groups_[g].child) {
      c.log_odds = n.log_odds;
      c.link = 0;
      if (n.link) attributes(c) = attributes_[n.link - 1];
    }
    dropAttributes(n);
    n.link = kInner | g;
    nodes_ += 8;
  }

  // OctoMap's pruneNode: eight equal leaf children collapse into `n`.
  bool prune(Node& n) {
    Group& g = children(n);
    const Node& first = g.child[0];
    if (std::isnan(first.log_odds) || hasChildren(first)) return false;
    const Attributes& a = attributesOf(first);
    for (unsigned i = 1; i < 8; ++i) {
      const Node& c = g.child[i];
      if (!(c.log_odds == first.log_odds) || hasChildren(c) || !(attributesOf(c) == a)) return false;
    }
    const uint32_t group = n.link & ~kInner;
    n.log_odds = first.log_odds;
    n.link = first.link;  // the first child's record moves up
    for (unsigned i = 1; i < 8; ++i) dropAttributes(g.child[i]);
    groups_.release(group);
    nodes_ -= 8;
    return true;
  }

  // OctoMap's updateOccupancyChildren: an inner node holds its children's maximum log-odds.
  void updateFromChildren(Node& n) {
    float max = -std::numeric_limits<float>::max();
    for (const Node& c : children(n).child)
      if (!std::isnan(c.log_odds) && c.log_odds > max) max = c.log_odds;
    n.log_odds = max;
  }

  const Attributes& attributesOf(const Node& n) const {
    static const Attributes never_hit;
    return !hasChildren(n) && n.link ? attributes_[n.link - 1] : never_hit;
  }
  // The leaf's record, created on first use.
  Attributes& attributes(Node& n) {
    if (!n.link) {
      n.link = attributes_.allocate() + 1;
      attributes_[n.link - 1] = Attributes{};
    }
    return attributes_[n.link - 1];
  }

  // OctoMap's search: the leaf holding `key` (pruned leaves included), or nullptr if unknown.
  const Node* search(const octomap::OcTreeKey& key) const {
    const Node* n = root();
    for (unsigned depth = 0; n && depth < kDepth && hasChildren(*n); ++depth) {
      const unsigned level = kDepth - 1 - depth;
      const unsigned pos = ((key[0] >> level) & 1) | (((key[1] >> level) & 1) << 1) | (((key[2] >> level) & 1) << 2);
      n = child(*n, pos);
    }
    return n;
  }

  // f(leaf, lowest-corner key, depth) for every leaf, in OctoMap's depth-first child order;
  // `keep(key, depth)` may skip whole subtrees.
  template <class Keep, class F>
  void forEachLeaf(Keep&& keep, F&& f) const {
    if (!empty()) visit(root_, octomap::OcTreeKey(0, 0, 0), 0, keep, f);
  }
  template <class F>
  void forEachLeaf(F&& f) const {
    forEachLeaf([](const octomap::OcTreeKey&, unsigned) { return true; }, f);
  }

  size_t nodeCount() const { return nodes_; }
  size_t leafCount() const { return nodes_ - groups_.live(); }  // one group per inner node
  size_t attributeRecords() const { return attributes_.live(); }
  size_t memoryBytes() const { return sizeof(*this) + groups_.memoryBytes() + attributes_.memoryBytes(); }

 private:
  uint32_t newGroup() {
    const uint32_t g = groups_.allocate();
    groups_[g] = Group{};
    return g;
  }
  void dropAttributes(Node& n) {
    if (!hasChildren(n) && n.link) attributes_.release(n.link - 1);
    if (!hasChildren(n)) n.link = 0;
  }
  template <class Keep, class F>
  void visit(const Node& n, const octomap::OcTreeKey& key, unsigned depth, Keep& keep, F& f) const {
    if (!keep(key, depth)) return;
    if (!hasChildren(n)) {
      f(n, key, depth);
      return;
    }
    const uint16_t half = static_cast<uint16_t>(1u << (kDepth - 1 - depth));
    const Group& g = children(n);
    for (unsigned i = 0; i < 8; ++i) {
      if (std::isnan(g.child[i].log_odds)) continue;
      const octomap::OcTreeKey k(key[0] + ((i & 1) ? half : 0), key[1] + ((i & 2) ? half : 0),
                                 key[2] + ((i & 4) ? half : 0));
      visit(g.child[i], k, depth + 1, keep, f);
    }
  }

  Node root_;
  size_t nodes_ = 0;
  ChunkPool<Group, 12> groups_;           // up to 256 KiB a chunk
  ChunkPool<Attributes, 12> attributes_;  // up to 48 KiB a chunk
};

}  // namespace layerpilot
