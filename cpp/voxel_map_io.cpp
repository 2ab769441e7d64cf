// File I/O of VoxelMap, kept apart from the map itself (as Bonxai keeps serialization apart):
// `.ot` with every attribute, `.bt` with occupancy only, and loading of stock OctoMap files.
#include "voxel_map.hpp"

#include <octomap/ColorOcTree.h>
#include <octomap/OcTree.h>

#include <fstream>
#include <stdexcept>
#include <type_traits>

namespace layerpilot {

void VoxelMap::save(const std::string& path) const {
  std::shared_lock lock(mutex_);
  if (!tree_.write(path)) throw std::runtime_error("cannot write " + path);
}

void VoxelMap::exportBt(const std::string& path) const {
  std::ofstream out(path, std::ios::binary);
  if (!out) throw std::runtime_error("cannot write " + path);
  std::shared_lock lock(mutex_);
  // OctoMap's binary header with the stock tree id, so every .bt reader takes the file as is.
  out << "# Octomap OcTree binary file\n#\n"
      << "id OcTree\nsize " << tree_.size() << "\nres " << tree_.getResolution() << "\ndata\n";
  tree_.writeBinaryData(out);
  if (!out) throw std::runtime_error("cannot write " + path);
}

namespace {

template <class SrcTree, class SrcNode>
void copyStructure(const SrcTree& src, const SrcNode* s, VoxelTree& dst, VoxelNode* d) {
  d->setLogOdds(s->getLogOdds());
  if constexpr (std::is_same_v<SrcNode, octomap::ColorOcTreeNode>) {
    const auto c = s->getColor();
    d->color = Rgb{c.r, c.g, c.b};
  }
  for (unsigned i = 0; i < 8; ++i)
    if (src.nodeChildExists(s, i)) copyStructure(src, src.getNodeChild(s, i), dst, dst.createNodeChild(d, i));
}

template <class SrcTree>
void copyTree(const SrcTree& src, VoxelTree& dst) {
  if (!src.getRoot()) return;
  dst.root = new VoxelNode();
  ++dst.tree_size;
  copyStructure(src, src.getRoot(), dst, dst.root);
}

bool endsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

}  // namespace

std::unique_ptr<VoxelMap> VoxelMap::load(const std::string& path, const SensorModel& model) {
  if (!std::ifstream(path).good()) throw std::runtime_error("cannot open " + path);
  std::unique_ptr<VoxelMap> map;
  if (endsWith(path, ".bt")) {
    // Read the header for the resolution, then the occupancy bits into a tree of our type.
    octomap::OcTree probe(0.1);
    if (!probe.readBinary(path)) throw std::runtime_error(path + ": not a readable OctoMap .bt file");
    map = std::make_unique<VoxelMap>(probe.getResolution(), model);
    copyTree(probe, map->tree_);
  } else {
    std::unique_ptr<octomap::AbstractOcTree> tree(octomap::AbstractOcTree::read(path));
    if (!tree) throw std::runtime_error(path + ": not a readable OctoMap .ot file");
    map = std::make_unique<VoxelMap>(tree->getResolution(), model);
    if (auto* own = dynamic_cast<VoxelTree*>(tree.get())) {
      map->tree_.swapContent(*own);
    } else if (auto* color = dynamic_cast<octomap::ColorOcTree*>(tree.get())) {
      copyTree(*color, map->tree_);
    } else if (auto* plain = dynamic_cast<octomap::OcTree*>(tree.get())) {
      copyTree(*plain, map->tree_);
    } else {
      throw std::runtime_error(path + ": unsupported tree type " + tree->getTreeType());
    }
  }
  map->applyModel();
  map->rebuildColumnIndex();
  return map;
}

}  // namespace layerpilot
