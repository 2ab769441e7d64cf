// Voxel keys as integers: Morton codes (OctoMap's depth-first child order), a flat hash map
// for endpoint accumulation, a sparse bit grid for de-duplicating free cells, and a radix sort.
#pragma once

#include <octomap/OcTreeKey.h>

#include <algorithm>
#include <deque>
#include <cstdint>
#include <memory>
#include <vector>

namespace layerpilot {

// Interleaves x, y, z so that (code >> 3*level) & 7 == OctoMap's computeChildIdx(key, level).
inline uint64_t spread3(uint64_t v) {
  v &= 0xffff;
  v = (v | (v << 32)) & 0x1f00000000ffffULL;
  v = (v | (v << 16)) & 0x1f0000ff0000ffULL;
  v = (v | (v << 8)) & 0x100f00f00f00f00fULL;
  v = (v | (v << 4)) & 0x10c30c30c30c30c3ULL;
  v = (v | (v << 2)) & 0x1249249249249249ULL;
  return v;
}

inline uint64_t compact3(uint64_t v) {
  v &= 0x1249249249249249ULL;
  v = (v ^ (v >> 2)) & 0x10c30c30c30c30c3ULL;
  v = (v ^ (v >> 4)) & 0x100f00f00f00f00fULL;
  v = (v ^ (v >> 8)) & 0x1f0000ff0000ffULL;
  v = (v ^ (v >> 16)) & 0x1f00000000ffffULL;
  v = (v ^ (v >> 32)) & 0xffff;
  return v;
}

inline uint64_t morton(const octomap::OcTreeKey& k) {
  return spread3(k[0]) | (spread3(k[1]) << 1) | (spread3(k[2]) << 2);
}

inline octomap::OcTreeKey unmorton(uint64_t c) {
  return octomap::OcTreeKey(static_cast<uint16_t>(compact3(c)), static_cast<uint16_t>(compact3(c >> 1)),
                            static_cast<uint16_t>(compact3(c >> 2)));
}

inline uint64_t packKey(const octomap::OcTreeKey& k) {
  return uint64_t(k[0]) | (uint64_t(k[1]) << 16) | (uint64_t(k[2]) << 32);
}

inline uint64_t mix64(uint64_t x) {
  x ^= x >> 33;
  x *= 0xff51afd7ed558ccdULL;
  x ^= x >> 33;
  return x;
}

// Open-addressing map from a 48-bit packed key to a uint32 index; never shrinks, no erase.
class FlatKeyIndex {
 public:
  static constexpr uint64_t kEmpty = ~0ULL;

  explicit FlatKeyIndex(size_t expected = 1024) {
    size_t cap = 16;
    while (cap < expected * 2) cap <<= 1;
    keys_.assign(cap, kEmpty);
    values_.resize(cap);
  }

  // Returns {index, inserted}: the stored index, or `value` if the key was new.
  std::pair<uint32_t, bool> insert(uint64_t key, uint32_t value) {
    if ((size_ + 1) * 2 > keys_.size()) grow();
    size_t mask = keys_.size() - 1;
    for (size_t i = mix64(key) & mask;; i = (i + 1) & mask) {
      if (keys_[i] == key) return {values_[i], false};
      if (keys_[i] == kEmpty) {
        keys_[i] = key;
        values_[i] = value;
        ++size_;
        return {value, true};
      }
    }
  }

  const uint32_t* find(uint64_t key) const {
    size_t mask = keys_.size() - 1;
    for (size_t i = mix64(key) & mask;; i = (i + 1) & mask) {
      if (keys_[i] == key) return &values_[i];
      if (keys_[i] == kEmpty) return nullptr;
    }
  }

  size_t size() const { return size_; }
  size_t memoryBytes() const { return keys_.capacity() * sizeof(uint64_t) + values_.capacity() * sizeof(uint32_t); }

 private:
  void grow() {
    std::vector<uint64_t> old_keys(keys_.size() * 2, kEmpty);
    std::vector<uint32_t> old_values(values_.size() * 2);
    old_keys.swap(keys_);
    old_values.swap(values_);
    size_ = 0;
    for (size_t i = 0; i < old_keys.size(); ++i)
      if (old_keys[i] != kEmpty) insert(old_keys[i], old_values[i]);
  }

  std::vector<uint64_t> keys_;
  std::vector<uint32_t> values_;
  size_t size_ = 0;
};

// A set of voxel keys stored as 16^3-bit blocks (Bonxai's idea): consecutive steps of a ray
// stay in one block, so marking a cell is a cached pointer and one bit operation.
class SparseBitGrid {
 public:
  // Sets the bit; returns true if it was not set before.
  bool testAndSet(uint16_t x, uint16_t y, uint16_t z) {
    const uint64_t block_id = uint64_t(x >> 4) | (uint64_t(y >> 4) << 12) | (uint64_t(z >> 4) << 24);
    // Rays from one origin keep revisiting the same blocks: a small direct-mapped cache in
    // front of the hash index answers most block look-ups.
    CacheEntry& slot = cache_[(block_id ^ (block_id >> 9) ^ (block_id >> 19)) & (kCacheSize - 1)];
    if (slot.id != block_id) {
      auto [index, inserted] = index_.insert(block_id, static_cast<uint32_t>(blocks_.size()));
      if (inserted) blocks_.emplace_back();
      slot = {block_id, &blocks_[index]};
    }
    const uint32_t bit = (x & 15) | ((y & 15) << 4) | ((z & 15) << 8);
    const uint64_t mask = 1ULL << (bit & 63);
    uint64_t& word = slot.block->words[bit >> 6];
    const bool was_set = word & mask;
    word |= mask;
    return !was_set;
  }

  bool contains(const octomap::OcTreeKey& k) const {
    const uint32_t* index = index_.find(packBlock(k));
    if (!index) return false;
    uint32_t bit = (k[0] & 15) | ((k[1] & 15) << 4) | ((k[2] & 15) << 8);
    return blocks_[*index].words[bit >> 6] & (1ULL << (bit & 63));
  }

  size_t memoryBytes() const { return sizeof(*this) + index_.memoryBytes() + blocks_.size() * sizeof(Block); }

 private:
  struct Block {
    uint64_t words[64] = {};
  };
  static uint64_t packBlock(const octomap::OcTreeKey& k) {
    return uint64_t(k[0] >> 4) | (uint64_t(k[1] >> 4) << 12) | (uint64_t(k[2] >> 4) << 24);
  }

  struct CacheEntry {
    uint64_t id = ~0ULL;
    Block* block = nullptr;
  };
  static constexpr size_t kCacheSize = 256;

  FlatKeyIndex index_{256};
  std::deque<Block> blocks_;  // stable addresses while growing
  CacheEntry cache_[kCacheSize];
};

// LSD radix sort of 64-bit values whose significant bits are below `bits` (16-bit digits).
inline void radixSort(std::vector<uint64_t>& v, int bits) {
  std::vector<uint64_t> tmp(v.size());
  std::vector<uint32_t> count(1 << 16);
  for (int shift = 0; shift < bits; shift += 16) {
    std::fill(count.begin(), count.end(), 0);
    for (uint64_t x : v) ++count[(x >> shift) & 0xffff];
    uint32_t sum = 0;
    for (auto& c : count) {
      uint32_t n = c;
      c = sum;
      sum += n;
    }
    for (uint64_t x : v) tmp[count[(x >> shift) & 0xffff]++] = x;
    v.swap(tmp);
  }
}

}  // namespace layerpilot
