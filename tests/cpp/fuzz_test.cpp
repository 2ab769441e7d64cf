// The file reader under damage: thousands of deterministic mutations of real map files (ours and
// OctoMap's, .ot and .bt) each either load as a well-formed map or fail with MapFileError naming
// what is wrong; nothing else (no other exception, no crash - the ctest build runs under
// AddressSanitizer and UndefinedBehaviorSanitizer, so an out-of-bounds read fails the run).
#include <gtest/gtest.h>

#include <fstream>
#include <iterator>
#include <random>

#include "reference_tree.hpp"

namespace layerpilot::test {
namespace {

struct Seed {
  std::string name, bytes;
};

std::vector<Seed> seeds() {
  SideBySide maps(0.5);
  std::mt19937 rng(3);
  for (int frame = 0; frame < 2; ++frame)
    maps.insert(makeCloud(randomFrame(rng, 300, 6.f)), rng, octomap::point3d(0, 0, 0), 1.f + frame, 8.0);
  std::ostringstream ot, bt;
  maps.stock.write(ot);
  maps.stock.writeBinaryConst(bt);
  return {{"layerpilot .ot", maps.ours.serialize(FileFormat::Ot)},
          {"layerpilot .bt", maps.ours.serialize(FileFormat::Bt)},
          {"OctoMap OcTree .ot", ot.str()},
          {"OctoMap OcTree .bt", bt.str()}};
}

// One random damage: bit flips, overwritten, inserted, deleted or repeated bytes, a cut, or a
// header number replaced by a hostile one.
std::string mutate(const std::string& in, std::mt19937& rng) {
  std::string s = in;
  auto at = [&](size_t n) { return std::uniform_int_distribution<size_t>(0, n)(rng); };
  auto byte = [&] { return static_cast<char>(std::uniform_int_distribution<int>(0, 255)(rng)); };
  const size_t data = s.find("\ndata\n") + 6;
  const bool in_header = at(3) == 0;
  auto where = [&] { return in_header ? at(data - 1) : data + at(s.size() - data - 1); };
  switch (at(7)) {
    case 0:
      for (size_t k = 1 + at(7); k-- > 0;) s[where()] ^= static_cast<char>(1u << at(7));
      break;
    case 1:
      for (size_t k = 1 + at(3); k-- > 0;) s[where()] = byte();
      break;
    case 2:
      s.resize(where());
      break;
    case 3: {
      const size_t pos = where();
      std::string junk(1 + at(15), '\0');
      for (char& c : junk) c = byte();
      s.insert(pos, junk);
      break;
    }
    case 4: {
      const size_t pos = where();
      s.erase(pos, 1 + at(15));
      break;
    }
    case 5: {
      const size_t pos = where(), len = 1 + at(31);
      s.insert(pos, s.substr(pos, len));
      break;
    }
    case 6: {
      static const char* const sizes[] = {"0", "1", "2", "9", "4294967297", "18446744073709551615", "999999999999999999", "-3", ""};
      const size_t line = s.find("\nsize ") + 6, end = s.find('\n', line);
      s.replace(line, end - line, sizes[at(8)]);
      break;
    }
    default: {
      static const char* const resolutions[] = {"0", "-1", "nan", "inf", "1e-320", "1e308", "0.0000001", "1e3", "0x10", ""};
      const size_t line = s.find("\nres ") + 5, end = s.find('\n', line);
      s.replace(line, end - line, resolutions[at(9)]);
      break;
    }
  }
  return s;
}

bool namesTheDamage(const std::string& message) {
  for (const char* what : {"empty", "truncated", "garbled", "trailing garbage", "unsupported tree type"})
    if (message.rfind(what, 0) == 0) return true;
  return false;
}

TEST(Fuzz, DamagedFilesLoadWellFormedOrFailWithAClearError) {
  std::mt19937 rng(2024);
  size_t loaded = 0, rejected = 0;
  for (const Seed& seed : seeds()) {
    ASSERT_NO_THROW(VoxelMap::parse(seed.bytes.data(), seed.bytes.size(), SensorModel{})) << seed.name;
    for (int i = 0; i < 2500; ++i) {
      const std::string damaged = mutate(seed.bytes, rng);
      try {
        const auto map = VoxelMap::parse(damaged.data(), damaged.size(), SensorModel{});
        // It loaded: a complete map that writes and reads back to the same tree.
        const std::string again = map->serialize(FileFormat::Ot);
        const auto back = VoxelMap::parse(again.data(), again.size(), SensorModel{});
        ASSERT_TRUE(sameNodes(nodesOf(*back), nodesOf(*map))) << seed.name << ", mutant " << i;
        ++loaded;
      } catch (const MapFileError& e) {
        ASSERT_TRUE(namesTheDamage(e.what())) << seed.name << ", mutant " << i << ": " << e.what();
        ++rejected;
      } catch (const std::exception& e) {
        FAIL() << seed.name << ", mutant " << i << ": not a MapFileError: " << e.what();
      }
    }
  }
  EXPECT_GT(rejected, 5000u);
  EXPECT_GT(loaded, 500u);  // bit flips in log-odds and colors keep a file well formed
}

// Found by the test above: an occupied leaf near the root (here the whole key space, 65,536 voxels
// a side) would fill billions of column-index entries; it is refused before anything is built.
TEST(Fuzz, AnOccupiedLeafNearTheRootIsRefused) {
  std::string ot = "# Octomap OcTree file\nid OcTree\nsize 1\nres 0.1\ndata\n";
  const float log_odds = 2.f;
  ot.append(reinterpret_cast<const char*>(&log_odds), sizeof(log_odds));
  ot.push_back('\0');  // no children: the root is a leaf
  try {
    VoxelMap::parse(ot.data(), ot.size(), SensorModel{});
    FAIL() << "loaded";
  } catch (const MapFileError& e) {
    EXPECT_STREQ(e.what(), "garbled node stream at byte 52: an occupied leaf at depth 0 (65536 voxels a side; at most 256 are read)");
  }
}

// A file cut anywhere in its header and at every 3rd byte of its node stream: reported as cut.
TEST(Fuzz, TruncationsAreReported) {
  for (const Seed& seed : seeds())
    for (size_t n = 0; n < seed.bytes.size(); n += n < seed.bytes.find("\ndata\n") + 6 ? 1 : 3) {
      try {
        VoxelMap::parse(seed.bytes.data(), n, SensorModel{});
        FAIL() << seed.name << " cut to " << n << " bytes loaded";
      } catch (const MapFileError& e) {
        const std::string what = e.what();
        EXPECT_TRUE(what.rfind("truncated", 0) == 0 || what.rfind("empty", 0) == 0 || what.rfind("garbled", 0) == 0)
            << seed.name << " cut to " << n << ": " << what;
      }
    }
}

}  // namespace
}  // namespace layerpilot::test
