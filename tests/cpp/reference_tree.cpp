#include "reference_tree.hpp"

#include <unordered_map>

namespace layerpilot::test {

std::istream& VoxelNode::readData(std::istream& s) {
  s.read(reinterpret_cast<char*>(&value), sizeof(value));
  s.read(reinterpret_cast<char*>(&attributes.color), sizeof(attributes.color));
  s.read(reinterpret_cast<char*>(&attributes.last_seen), sizeof(attributes.last_seen));
  s.read(reinterpret_cast<char*>(&attributes.min_distance), sizeof(attributes.min_distance));
  return s;
}

std::ostream& VoxelNode::writeData(std::ostream& s) const {
  s.write(reinterpret_cast<const char*>(&value), sizeof(value));
  s.write(reinterpret_cast<const char*>(&attributes.color), sizeof(attributes.color));
  s.write(reinterpret_cast<const char*>(&attributes.last_seen), sizeof(attributes.last_seen));
  s.write(reinterpret_cast<const char*>(&attributes.min_distance), sizeof(attributes.min_distance));
  return s;
}

VoxelTree::Registration VoxelTree::registration;

VoxelTree::Registration::Registration() {
  auto* tree = new VoxelTree(0.1);
  tree->clearKeyRays();
  AbstractOcTree::registerTreeType(tree);
}

VoxelTree::VoxelTree(double resolution) : OccupancyOcTreeBase<VoxelNode>(resolution) { registration.ensureLinking(); }

void VoxelTree::insert(const Cloud& cloud, const Colors& colors, const octomap::point3d& origin, float stamp,
                       double max_range) {
  struct Hits {
    uint32_t rgb[3] = {0, 0, 0};
    uint32_t count = 0;
    float min_distance = std::numeric_limits<float>::infinity();
  };
  std::unordered_map<octomap::OcTreeKey, Hits, octomap::OcTreeKey::KeyHash> hits;
  for (size_t i = 0; i < cloud.octomap.size(); ++i) {
    const octomap::point3d& p = cloud.octomap[i];
    Hits& h = hits[coordToKey(p)];
    const float dx = p.x() - origin.x(), dy = p.y() - origin.y(), dz = p.z() - origin.z();
    h.min_distance = std::min(h.min_distance, std::sqrt(dx * dx + dy * dy + dz * dz));
    for (int c = 0; c < 3 && colors.rows(); ++c) h.rgb[c] += colors(static_cast<Eigen::Index>(i), c);
    ++h.count;
  }
  octomap::KeySet free_cells, occupied_cells;
  computeDiscreteUpdate(cloud.octomap, origin, free_cells, occupied_cells, max_range);
  for (const auto& key : free_cells) updateNode(key, false, true);
  for (const auto& key : occupied_cells) {
    const VoxelNode* before = search(key);
    // At the upper bound updateNode would stop at a pruned leaf; setNodeValue expands it down to
    // the voxel, whose attributes change while its log-odds stay.
    VoxelNode* node = before && before->getLogOdds() >= clamping_thres_max ? setNodeValue(key, clamping_thres_max, true)
                                                                            : updateNode(key, true, true);
    const Hits& h = hits.at(key);
    Attributes& a = node->attributes;
    a.last_seen = stamp;
    a.min_distance = std::min(a.min_distance, h.min_distance);
    if (colors.rows())
      a.color = Rgb{static_cast<uint8_t>((h.rgb[0] + h.count / 2) / h.count),
                    static_cast<uint8_t>((h.rgb[1] + h.count / 2) / h.count),
                    static_cast<uint8_t>((h.rgb[2] + h.count / 2) / h.count)};
  }
  updateInnerOccupancy();
  prune();
}

}  // namespace layerpilot::test
