// Thin pybind11 layer (`layerpilot._core`): argument checks live in Python (layerpilot.map),
// arrays leave C++ without copies, and the GIL is released while the map works.
#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "voxel_map.hpp"

namespace py = pybind11;
using namespace layerpilot;

namespace {

template <class T>
py::array_t<T> toArray(std::vector<T>&& v, std::vector<py::ssize_t> shape) {
  auto* owned = new std::vector<T>(std::move(v));
  py::capsule free_when_done(owned, [](void* p) { delete static_cast<std::vector<T>*>(p); });
  return py::array_t<T>(shape, owned->data(), free_when_done);
}

}  // namespace

PYBIND11_MODULE(_core, m) {
  m.doc() = "layerpilot C++ core: attribute octree on OctoMap with a column index";

  py::class_<SensorModel>(m, "_SensorModel")
      .def(py::init<>())
      .def_readwrite("prob_hit", &SensorModel::prob_hit)
      .def_readwrite("prob_miss", &SensorModel::prob_miss)
      .def_readwrite("clamp_min", &SensorModel::clamp_min)
      .def_readwrite("clamp_max", &SensorModel::clamp_max)
      .def_readwrite("occupied_threshold", &SensorModel::occupied_threshold);

  py::register_exception<MapFileError>(m, "_MapFileError", PyExc_ValueError);

  py::class_<VoxelMap>(m, "_VoxelMap")
      .def(py::init<double, const SensorModel&>())
      .def_static("parse",
                  [](py::buffer data, const SensorModel& model) {
                    const py::buffer_info info = data.request();
                    if (info.ndim != 1 || info.itemsize != 1 || info.strides[0] != 1)
                      throw std::invalid_argument("data: expected contiguous bytes");
                    py::gil_scoped_release release;
                    return VoxelMap::parse(static_cast<const char*>(info.ptr), info.size, model);
                  })
      .def_property_readonly("resolution", &VoxelMap::resolution)
      .def("insert",
           [](VoxelMap& map, const Eigen::Ref<const Points>& points, const Eigen::Ref<const Colors>& colors,
              const Eigen::Vector3d& origin, double stamp, double max_range) {
             InsertResult r;
             {
               py::gil_scoped_release release;
               r = map.insert(points, colors, origin, stamp, max_range);
             }
             return py::make_tuple(r.points_used, r.points_dropped, r.voxels_updated, r.voxels_occupied);
           })
      .def("column_layers",
           [](const VoxelMap& map, int64_t kx, int64_t ky, int width, int height) {
             ColumnWindow w;
             {
               py::gil_scoped_release release;
               w = map.columnLayers(kx, ky, width, height);
             }
             const py::ssize_t h = height, wd = width;
             return py::make_tuple(toArray(std::move(w.observed), {h, wd}), toArray(std::move(w.elevation), {h, wd}),
                                   toArray(std::move(w.color), {h, wd, 3}), toArray(std::move(w.last_seen), {h, wd}),
                                   toArray(std::move(w.min_distance), {h, wd}));
           })
      .def("occupancy", &VoxelMap::occupancy, py::call_guard<py::gil_scoped_release>())
      .def("raycast", &VoxelMap::raycast, py::call_guard<py::gil_scoped_release>())
      .def("voxels",
           [](const VoxelMap& map, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, double min_occupancy) {
             VoxelSet s;
             {
               py::gil_scoped_release release;
               s = map.voxels(lo, hi, min_occupancy);
             }
             const py::ssize_t n = s.size();
             return py::make_tuple(toArray(std::move(s.centers), {n, 3}), toArray(std::move(s.occupancy), {n}),
                                   toArray(std::move(s.color), {n, 3}), toArray(std::move(s.last_seen), {n}),
                                   toArray(std::move(s.min_distance), {n}));
           })
      .def("serialize",
           [](const VoxelMap& map, bool bt) {
             std::string stream;
             {
               py::gil_scoped_release release;
               stream = map.serialize(bt ? FileFormat::Bt : FileFormat::Ot);
             }
             return py::bytes(stream);
           })
      .def("stats", [](const VoxelMap& map) {
        MapStats s;
        {
          py::gil_scoped_release release;
          s = map.stats();
        }
        py::dict d;
        d["resolution"] = s.resolution;
        d["nodes"] = s.nodes;
        d["leaves"] = s.leaves;
        d["occupied_leaves"] = s.occupied_leaves;
        d["attribute_records"] = s.attribute_records;
        d["tree_bytes"] = s.tree_bytes;
        d["column_index_bytes"] = s.column_index_bytes;
        d["insert_scratch_bytes"] = s.insert_scratch_bytes;
        d["total_bytes"] = s.total_bytes;
        d["node_bytes"] = s.node_bytes;
        d["bounds_min"] = py::make_tuple(s.min[0], s.min[1], s.min[2]);
        d["bounds_max"] = py::make_tuple(s.max[0], s.max[1], s.max[2]);
        return d;
      });
}
