// Map files between layerpilot and OctoMap, both ways: what one writes the other reads to the
// same tree (.bt: the same bytes as OctoMap's own writer; .ot: every log-odds and attribute).
#include <gtest/gtest.h>
#include <octomap/OcTree.h>

#include <fstream>
#include <iterator>
#include <random>

#include "reference_tree.hpp"

namespace layerpilot::test {
namespace {

std::unique_ptr<VoxelMap> parse(const std::string& bytes) {
  return VoxelMap::parse(bytes.data(), bytes.size(), SensorModel{});
}

// From the `size` line on: OctoMap's writers and ours differ only in the comment lines, and a .bt
// of the attribute reference names its own tree type.
std::string fromSize(const std::string& stream) {
  const size_t size = stream.find("\nsize ");
  return size == std::string::npos ? std::string() : stream.substr(size + 1);
}

std::string btOf(const octomap::AbstractOccupancyOcTree& tree) {
  std::ostringstream out;
  EXPECT_TRUE(tree.writeBinaryConst(out));
  return out.str();
}

// The same random frames (with color and time) in layerpilot's map and both OctoMap trees.
struct Maps : SideBySide {
  Maps() : SideBySide(0.5) {
    std::mt19937 rng(21);
    for (int frame = 0; frame < 5; ++frame)
      insert(makeCloud(randomFrame(rng, 2000, 15.f)), rng, octomap::point3d(0.3f * frame, -0.2f, 0.1f),
             10.f + frame, 18.0);
  }
};

class Files : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { maps_ = new Maps; }
  static void TearDownTestSuite() { delete maps_; }
  static Maps* maps_;
};
Maps* Files::maps_ = nullptr;

TEST_F(Files, TheTreesAreEqualToBeginWith) {
  ASSERT_TRUE(maps_->same());
  EXPECT_GT(maps_->ours.stats().attribute_records, 1000u);
}

TEST_F(Files, OurBtIsOctoMapsOwnBtByteForByteAndEachReadsTheOther) {
  const std::string ours = maps_->ours.serialize(FileFormat::Bt);
  ASSERT_GT(ours.size(), 10000u);
  EXPECT_EQ(fromSize(ours), fromSize(btOf(maps_->reference))) << "OctoMap writes the same tree otherwise";
  octomap::OcTree read_ours(0.1);
  std::istringstream in_ours(ours);
  ASSERT_TRUE(read_ours.readBinary(in_ours));
  EXPECT_TRUE(sameNodes(nodesOf(read_ours), nodesOf(*parse(ours)))) << "OctoMap and layerpilot reading our .bt";

  const std::string theirs = btOf(maps_->stock);
  octomap::OcTree read_theirs(0.1);
  std::istringstream in_theirs(theirs);
  ASSERT_TRUE(read_theirs.readBinary(in_theirs));
  EXPECT_TRUE(sameNodes(nodesOf(*parse(theirs)), nodesOf(read_theirs))) << "layerpilot reading OctoMap's .bt";
}

TEST_F(Files, OctoMapsOtIsReadWithEveryLogOdds) {
  std::ostringstream out;
  ASSERT_TRUE(maps_->stock.write(out));  // id OcTree
  const auto read = parse(out.str());
  EXPECT_TRUE(sameNodes(nodesOf(*read), nodesOf(maps_->stock)));
  EXPECT_EQ(fromSize(read->serialize(FileFormat::Bt)), fromSize(btOf(maps_->stock)));
}

TEST_F(Files, OurOtIsReadByOctoMapWithEveryAttributeAndWrittenBackByteForByte) {
  const std::string ours = maps_->ours.serialize(FileFormat::Ot);
  std::istringstream in(ours);
  std::unique_ptr<octomap::AbstractOcTree> read(octomap::AbstractOcTree::read(in));
  auto* tree = dynamic_cast<VoxelTree*>(read.get());
  ASSERT_NE(tree, nullptr) << "OctoMap did not read a LayerpilotVoxelTree";
  EXPECT_TRUE(sameNodes(nodesOf(*tree), nodesOf(maps_->ours)));  // log-odds and every attribute
  size_t hit = 0;  // leaves with a color, a time and a distance of their own
  for (auto it = tree->begin_leafs(); it != tree->end_leafs(); ++it) hit += std::isfinite(it->attributes.last_seen);
  EXPECT_EQ(hit, maps_->ours.stats().attribute_records);

  std::ostringstream back;
  ASSERT_TRUE(tree->write(back));
  EXPECT_EQ(back.str(), ours) << "OctoMap wrote back other bytes than it read";
  EXPECT_EQ(parse(back.str())->serialize(FileFormat::Ot), ours);
}

TEST(RealFiles, Geb079BtReadsAsOctoMapReadsIt) {
  const std::string path = std::string(LAYERPILOT_OCTOMAP_DATA) + "/geb079.bt";
  std::ifstream file(path, std::ios::binary);
  ASSERT_TRUE(file) << "reference data missing: " << path;
  const std::string bytes((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
  octomap::OcTree ref(0.1);
  std::istringstream in(bytes);
  ASSERT_TRUE(ref.readBinary(in));
  const auto map = parse(bytes);
  const auto expected = nodesOf(ref);
  EXPECT_GT(expected.size(), 50000u);
  EXPECT_TRUE(sameNodes(nodesOf(*map), expected));
  EXPECT_EQ(fromSize(map->serialize(FileFormat::Bt)), fromSize(bytes));
}

}  // namespace
}  // namespace layerpilot::test
