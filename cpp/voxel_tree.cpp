#include "voxel_tree.hpp"

namespace layerpilot {

VoxelTree::VoxelTree(double resolution) : OccupancyOcTreeBase<VoxelNode>(resolution) {
  registration_.ensureLinking();
}

VoxelTree::StaticMemberInitializer::StaticMemberInitializer() {
  auto* tree = new VoxelTree(0.1);
  tree->clearKeyRays();
  octomap::AbstractOcTree::registerTreeType(tree);
}

VoxelTree::StaticMemberInitializer VoxelTree::registration_;

}  // namespace layerpilot
