// Per-column index of occupied voxels, kept up to date by insertion, so column layers for a
// window are a copy out of dense tiles instead of a walk over the octree.
#pragma once

#include <algorithm>
#include <cstdint>
#include <memory>
#include <unordered_map>

#include "compact_octree.hpp"

namespace layerpilot {

// 16 bytes: how many voxels of the column are occupied, the highest one, and its attributes.
struct Column {
  uint16_t occupied = 0;  // voxels above the occupied threshold; 0 = the column shows nothing
  uint16_t top = 0;       // z key of the highest of them (valid if occupied > 0)
  Rgb color;              // attributes of the top voxel, cached
  float last_seen = 0.f;
  float min_distance = 0.f;

  void setTopAttributes(const Attributes& a) {
    color = a.color;
    last_seen = a.last_seen;
    min_distance = a.min_distance;
  }
};
static_assert(sizeof(Column) == 16);

class ColumnIndex {
 public:
  static constexpr int kTileBits = 3;  // tiles of 8 x 8 columns: little waste where a scan is sparse
  static constexpr int kTileSize = 1 << kTileBits;

  Column& at(uint16_t x, uint16_t y) {
    auto& tile = tiles_[tileId(x, y)];
    if (!tile) tile = std::make_unique<Tile>();
    return tile->columns[cellIndex(x, y)];
  }

  // f(x, y, column) for every column of the window [x0, x0 + width) x [y0, y0 + height) that
  // shows something, one tile look-up per 8 x 8 columns.
  template <class F>
  void forEachShowing(int64_t x0, int64_t y0, int width, int height, F&& f) const {
    const int64_t x_end = std::min<int64_t>(x0 + width, 0x10000), y_end = std::min<int64_t>(y0 + height, 0x10000);
    const int64_t x_begin = std::max<int64_t>(x0, 0), y_begin = std::max<int64_t>(y0, 0);
    for (int64_t ty = y_begin & ~int64_t(kTileSize - 1); ty < y_end; ty += kTileSize)
      for (int64_t tx = x_begin & ~int64_t(kTileSize - 1); tx < x_end; tx += kTileSize) {
        auto it = tiles_.find(tileId(static_cast<uint16_t>(tx), static_cast<uint16_t>(ty)));
        if (it == tiles_.end()) continue;
        for (int64_t y = std::max(ty, y_begin); y < std::min(ty + kTileSize, y_end); ++y)
          for (int64_t x = std::max(tx, x_begin); x < std::min(tx + kTileSize, x_end); ++x) {
            const Column& c = it->second->columns[cellIndex(static_cast<uint16_t>(x), static_cast<uint16_t>(y))];
            if (c.occupied > 0) f(x, y, c);
          }
      }
  }

  // `count` voxels up to `z` became occupied: returns true if `z` is now the column's top.
  static bool addOccupied(Column& c, uint16_t z, uint16_t count = 1) {
    const bool top = c.occupied == 0 || z > c.top;
    c.occupied += count;
    if (top) c.top = z;
    return top;
  }

  // A voxel stopped being occupied: returns true if it was the top; the caller then finds the
  // next one down (`occupied_below(z)`) and refreshes the attributes.
  template <class OccupiedAt>
  static bool removeOccupied(Column& c, uint16_t z, OccupiedAt&& occupied_at) {
    --c.occupied;
    if (z != c.top) return false;
    if (c.occupied > 0)
      for (uint16_t below = z; below-- > 0;)
        if (occupied_at(below)) {
          c.top = below;
          break;
        }
    return true;
  }

  void clear() { tiles_.clear(); }

  // Tiles, the hash table's buckets and nodes (a key, a pointer and a link each).
  size_t memoryBytes() const {
    return tiles_.size() * (sizeof(Tile) + 3 * sizeof(void*)) + tiles_.bucket_count() * sizeof(void*);
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
