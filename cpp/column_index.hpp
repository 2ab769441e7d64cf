// Per-column index of occupied voxels, kept up to date by insertion, so column layers for a
// window are a copy out of dense tiles instead of a walk over the octree.
#pragma once

#include <algorithm>
#include <cstdint>
#include <memory>
#include <unordered_map>
#include <vector>

#include "voxel_tree.hpp"

namespace layerpilot {

struct Column {
  std::vector<uint16_t> occupied_z;  // z keys of voxels above the occupied threshold, ascending
  int32_t top = -1;                  // highest of them, -1 = none
  Rgb color;                         // attributes of the top voxel, cached
  float last_seen = 0.f;
  float min_distance = 0.f;

  void setTopAttributes(const VoxelNode& n) {
    color = n.color;
    last_seen = n.last_seen;
    min_distance = n.min_distance;
  }
};

class ColumnIndex {
 public:
  static constexpr int kTileBits = 6;  // tiles of 64 x 64 columns
  static constexpr int kTileSize = 1 << kTileBits;

  Column& at(uint16_t x, uint16_t y) {
    auto& tile = tiles_[tileId(x, y)];
    if (!tile) tile = std::make_unique<Tile>();
    return tile->columns[cellIndex(x, y)];
  }

  const Column* find(uint16_t x, uint16_t y) const {
    auto it = tiles_.find(tileId(x, y));
    return it == tiles_.end() ? nullptr : &it->second->columns[cellIndex(x, y)];
  }

  // A voxel became occupied: returns true if it is now the column's top.
  static bool addOccupied(Column& c, uint16_t z) {
    auto it = std::lower_bound(c.occupied_z.begin(), c.occupied_z.end(), z);
    if (it == c.occupied_z.end() || *it != z) c.occupied_z.insert(it, z);
    if (z > c.top) {
      c.top = z;
      return true;
    }
    return false;
  }

  // A voxel stopped being occupied: returns true if the top changed (caller refreshes attributes).
  static bool removeOccupied(Column& c, uint16_t z) {
    auto it = std::lower_bound(c.occupied_z.begin(), c.occupied_z.end(), z);
    if (it != c.occupied_z.end() && *it == z) c.occupied_z.erase(it);
    if (z != c.top) return false;
    c.top = c.occupied_z.empty() ? -1 : c.occupied_z.back();
    return true;
  }

  void clear() { tiles_.clear(); }

  size_t memoryBytes() const {
    size_t bytes = tiles_.size() * (sizeof(Tile) + 32);
    for (const auto& [id, tile] : tiles_)
      for (const auto& c : tile->columns) bytes += c.occupied_z.capacity() * sizeof(uint16_t);
    return bytes;
  }

 private:
  struct Tile {
    Column columns[kTileSize * kTileSize];
  };
  static uint32_t tileId(uint16_t x, uint16_t y) {
    return (uint32_t(x >> kTileBits) << 16) | uint32_t(y >> kTileBits);
  }
  static uint32_t cellIndex(uint16_t x, uint16_t y) {
    return ((y & (kTileSize - 1)) << kTileBits) | (x & (kTileSize - 1));
  }

  std::unordered_map<uint32_t, std::unique_ptr<Tile>> tiles_;
};

}  // namespace layerpilot
