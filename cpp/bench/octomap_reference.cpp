// `layerpilot.bench._octomap`: stock OctoMap (Debian's library, the one the map links) for
// `layerpilot bench map` and the Python tests that set layerpilot's map beside it. Not part of
// the map: the production module `_core` has no OctoMap tree in it.
#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <Eigen/Core>
#include <octomap/OcTree.h>

#include <chrono>
#include <vector>

namespace py = pybind11;

namespace {

using Points = Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor>;

struct OcTree {
  octomap::OcTree tree;
  explicit OcTree(double resolution) : tree(resolution) {}

  // insertPointCloud; returns milliseconds.
  double insert(const Eigen::Ref<const Points>& points, const Eigen::Vector3d& origin, double max_range,
                bool discretize) {
    octomap::Pointcloud cloud;
    cloud.reserve(points.rows());
    for (Eigen::Index i = 0; i < points.rows(); ++i) cloud.push_back(points(i, 0), points(i, 1), points(i, 2));
    const octomap::point3d o(origin.x(), origin.y(), origin.z());
    py::gil_scoped_release release;
    const auto t0 = std::chrono::steady_clock::now();
    tree.insertPointCloud(cloud, o, max_range, false, discretize);
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  }

  // Every finest-level voxel (pruned leaves expanded): centres (n, 3) and occupancy probability,
  // computed as layerpilot's VoxelMap.voxels computes them.
  py::tuple voxels() const {
    std::vector<float> centers, occupancy;
    const unsigned depth = tree.getTreeDepth();
    for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
      const octomap::OcTreeKey base = it.getIndexKey();
      const unsigned span = 1u << (depth - it.getDepth());
      const float p = static_cast<float>(octomap::probability(it->getLogOdds()));
      for (unsigned dx = 0; dx < span; ++dx)
        for (unsigned dy = 0; dy < span; ++dy)
          for (unsigned dz = 0; dz < span; ++dz) {
            centers.push_back(static_cast<float>(tree.keyToCoord(static_cast<octomap::key_type>(base[0] + dx))));
            centers.push_back(static_cast<float>(tree.keyToCoord(static_cast<octomap::key_type>(base[1] + dy))));
            centers.push_back(static_cast<float>(tree.keyToCoord(static_cast<octomap::key_type>(base[2] + dz))));
            occupancy.push_back(p);
          }
    }
    const py::ssize_t n = static_cast<py::ssize_t>(occupancy.size());
    return py::make_tuple(py::array_t<float>({n, py::ssize_t(3)}, centers.data()),
                          py::array_t<float>({n}, occupancy.data()));
  }
};

}  // namespace

PYBIND11_MODULE(_octomap, m) {
  m.doc() = "stock OctoMap OcTree, the reference of layerpilot's benchmarks and tests";
  py::class_<OcTree>(m, "OcTree")
      .def(py::init<double>())
      .def("insert", &OcTree::insert, "insertPointCloud; returns milliseconds")
      .def("voxels", &OcTree::voxels, "every finest-level voxel: centres (n, 3), occupancy probability")
      .def("leaves", [](const OcTree& r) { return r.tree.getNumLeafNodes(); })
      .def("memory_usage", [](const OcTree& r) { return r.tree.memoryUsage(); });
}
