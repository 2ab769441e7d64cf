// File I/O of VoxelMap, kept apart from the map itself (as Bonxai keeps serialization apart):
// whole OctoMap streams in memory, `.ot` with every attribute, `.bt` with occupancy only.
//
// OctoMap's own readers trust the stream: a truncated file reads as a smaller tree, garbage reads
// as nodes, and a short read leaves bytes uninitialized. So parse() first walks the WHOLE stream
// without allocating (header fields, every node, the exact end) and only then builds the tree
// from bytes known to be well formed. A `.ot` of layerpilot's is OctoMap's format for a node of
// log-odds, color (3 bytes), last seen and min distance (float32 each): tree id LayerpilotVoxelTree.
#include "voxel_map.hpp"

#include <octomap/ColorOcTree.h>
#include <octomap/OcTree.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <sstream>
#include <string_view>

namespace layerpilot {
namespace {

constexpr std::string_view kOtMagic = "# Octomap OcTree file";
constexpr std::string_view kBtMagic = "# Octomap OcTree binary file";
constexpr size_t kMaxHeader = 4096;  // OctoMap writes about 150 bytes
constexpr unsigned kTreeDepth = 16;
constexpr double kMaxResolution = 1000.0;  // metres; anything larger is a garbled header
// An occupied leaf fills a column-index entry for each of its columns (cpp/column_index.hpp), so
// a leaf of the upper levels (a damaged file: up to 65,536² columns) would take the loader down.
// Depth 8 is a cube of 256 voxels a side, far beyond any surface a sensor sees as one.
constexpr unsigned kMinOccupiedLeafDepth = 8;

// Bytes per node that each tree type's writeData() emits, before the 1-byte child mask.
static_assert(sizeof(Rgb) == 3 && sizeof(octomap::ColorOcTreeNode::Color) == 3);
constexpr size_t kOcTreeNodeBytes = sizeof(float);
constexpr size_t kColorNodeBytes = sizeof(float) + sizeof(octomap::ColorOcTreeNode::Color);
constexpr size_t kVoxelNodeBytes = sizeof(float) + sizeof(Rgb) + 2 * sizeof(float);
constexpr size_t kMinDistanceOffset = sizeof(float) + sizeof(Rgb) + sizeof(float);

[[noreturn]] void fail(const std::string& what) { throw MapFileError(what); }

std::string quoted(std::string_view s) {
  std::string out = "'";
  for (char c : s.substr(0, 40)) out += (c >= 32 && c < 127) ? c : '?';
  return out + (s.size() > 40 ? "...'" : "'");
}

struct Header {
  FileFormat format = FileFormat::Ot;
  std::string id;
  uint64_t size = 0;  // nodes
  double res = 0.0;
  size_t data_begin = 0;
};

uint64_t parseSize(std::string_view v) {
  if (v.empty() || v.size() > 18 || v.find_first_not_of("0123456789") != std::string_view::npos)
    fail("garbled header: size " + quoted(v) + " is not a node count");
  return std::strtoull(std::string(v).c_str(), nullptr, 10);
}

double parseResolution(std::string_view v) {
  const std::string s(v);
  char* end = nullptr;
  const double res = std::strtod(s.c_str(), &end);
  if (s.empty() || end != s.c_str() + s.size() || !std::isfinite(res) || res <= 0.0 || res > kMaxResolution)
    fail("garbled header: res " + quoted(v) + " is not a resolution in (0, 1000] m");
  return res;
}

// OctoMap's text header: the magic first line, then `#` comments, `id`, `size`, `res`, and `data`
// on a line of its own, after which the node stream begins. Anything else is a garbled header.
Header parseHeader(const char* data, size_t n) {
  if (n == 0) fail("empty: the file has 0 bytes");
  const std::string_view text(data, std::min(n, kMaxHeader));
  auto opens = [&](std::string_view magic) {
    const size_t k = std::min(text.size(), magic.size());
    return text.substr(0, k) == magic.substr(0, k);
  };
  if (!opens(kOtMagic) && !opens(kBtMagic))
    fail("garbled header: not an OctoMap file (it starts with " + quoted(text.substr(0, text.find('\n'))) + ")");
  Header h;
  bool have_id = false, have_size = false, have_res = false;
  for (size_t pos = 0, line_no = 0;; ++line_no) {
    const size_t eol = text.find('\n', pos);
    if (eol == std::string_view::npos) {
      if (n <= kMaxHeader) fail("truncated: the file ends inside the header at byte " + std::to_string(n));
      fail("garbled header: no 'data' line in the first " + std::to_string(kMaxHeader) + " bytes");
    }
    std::string_view line = text.substr(pos, eol - pos);
    pos = eol + 1;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (line_no == 0) {
      if (line.substr(0, kBtMagic.size()) == kBtMagic)
        h.format = FileFormat::Bt;
      else if (line.substr(0, kOtMagic.size()) != kOtMagic)
        fail("garbled header: the first line " + quoted(line) + " is not OctoMap's");
      continue;
    }
    if (line.empty() || line[0] == '#') continue;
    if (line == "data") {
      h.data_begin = pos;
      break;
    }
    const size_t space = line.find(' ');
    const std::string_view key = line.substr(0, space);
    const std::string_view value = space == std::string_view::npos ? std::string_view() : line.substr(space + 1);
    bool* seen = key == "id" ? &have_id : key == "size" ? &have_size : key == "res" ? &have_res : nullptr;
    if (!seen || *seen) fail("garbled header: unexpected line " + quoted(line));
    *seen = true;
    if (key == "id") {
      if (value.empty() || value.find_first_of(" \t") != std::string_view::npos)
        fail("garbled header: id " + quoted(value) + " is not a tree type");
      h.id = value;
    } else if (key == "size") {
      h.size = parseSize(value);
    } else {
      h.res = parseResolution(value);
    }
  }
  if (!have_id || !have_size || !have_res) fail("garbled header: it lacks an id, size or res line");
  return h;
}

size_t nodeBytes(const Header& h) {
  if (h.id == "LayerpilotVoxelTree") return kVoxelNodeBytes;
  if (h.id == "ColorOcTree") return kColorNodeBytes;
  if (h.id == "OcTree") return kOcTreeNodeBytes;
  fail("unsupported tree type " + quoted(h.id) + " (reads LayerpilotVoxelTree, OcTree, ColorOcTree)");
}

struct Walk {
  size_t end = 0;  // byte after the last node
  uint64_t nodes = 0;
};

// Depth-first walk with one counter per open level: children (`.ot`) or inner children (`.bt`)
// still to read. `read(depth)` consumes one record and returns its counter.
template <class ReadRecord>
void walkDepthFirst(ReadRecord&& read) {
  unsigned pending[kTreeDepth + 1];
  unsigned open = 0;
  do {
    const unsigned count = read(open);
    if (open > 0) --pending[open - 1];
    pending[open++] = count;
    while (open > 0 && pending[open - 1] == 0) --open;
  } while (open > 0);
}

std::string byteAt(size_t pos) { return " at byte " + std::to_string(pos); }

void checkOccupiedLeafDepth(unsigned depth, size_t pos) {
  if (depth < kMinOccupiedLeafDepth)
    fail("garbled node stream" + byteAt(pos) + ": an occupied leaf at depth " + std::to_string(depth) + " (" +
         std::to_string(1u << (kTreeDepth - depth)) + " voxels a side; at most " +
         std::to_string(1u << (kTreeDepth - kMinOccupiedLeafDepth)) + " are read)");
}

// `.ot` (OcTreeBaseImpl::writeNodesRecurs): per node its data, then one bit per existing child.
// `occupied_log`: the map's occupied threshold, for checkOccupiedLeafDepth.
Walk walkOt(const char* d, size_t n, const Header& h, float occupied_log) {
  const size_t record = nodeBytes(h) + 1;
  const bool voxel_tree = record == kVoxelNodeBytes + 1;
  Walk w{h.data_begin, 0};
  if (h.size == 0) return w;
  walkDepthFirst([&](unsigned depth) -> unsigned {
    if (n - w.end < record) {
      const bool fits = h.size <= (SIZE_MAX - h.data_begin) / record;
      const std::string expected = fits ? " of " + std::to_string(h.data_begin + h.size * record) : "";
      fail("truncated: the file ends" + byteAt(n) + expected + " inside the node stream (" +
           std::to_string(w.nodes) + " of " + std::to_string(h.size) + " nodes read)");
    }
    const char* p = d + w.end;
    float log_odds, min_distance;
    std::memcpy(&log_odds, p, sizeof(float));
    if (!std::isfinite(log_odds)) fail("garbled node stream" + byteAt(w.end) + ": occupancy is not a number");
    if (voxel_tree) {
      std::memcpy(&min_distance, p + kMinDistanceOffset, sizeof(float));
      if (!(min_distance >= 0.f)) fail("garbled node stream" + byteAt(w.end) + ": negative or NaN distance");
    }
    const auto mask = static_cast<uint8_t>(p[record - 1]);
    if (mask != 0 && depth == kTreeDepth)
      fail("garbled node stream" + byteAt(w.end) + ": a finest-level voxel has children");
    if (mask == 0 && log_odds >= occupied_log) checkOccupiedLeafDepth(depth, w.end);
    w.end += record;
    ++w.nodes;
    return static_cast<unsigned>(__builtin_popcount(mask));
  });
  return w;
}

// `.bt` (OccupancyOcTreeBase::writeBinaryNode): per inner node two bytes, two bits per child
// (01 free leaf, 10 occupied leaf, 11 inner node, 00 none); inner children follow depth first.
Walk walkBt(const char* d, size_t n, const Header& h) {
  Walk w{h.data_begin, 0};
  if (h.size == 0) return w;
  w.nodes = 1;  // the root
  walkDepthFirst([&](unsigned depth) -> unsigned {
    if (n - w.end < 2)
      fail("truncated: the file ends" + byteAt(n) + " inside the node stream (" + std::to_string(w.nodes) +
           " of " + std::to_string(h.size) + " nodes read)");
    const unsigned bits = static_cast<uint8_t>(d[w.end]) | static_cast<uint8_t>(d[w.end + 1]) << 8;
    unsigned children = 0, inner = 0;
    for (unsigned i = 0; i < 8; ++i) {
      const unsigned code = (bits >> (2 * i)) & 3;
      children += code != 0;
      inner += code == 3;
      if (code == 2) checkOccupiedLeafDepth(depth + 1, w.end);
    }
    if (children == 0 && depth > 0)
      fail("garbled node stream" + byteAt(w.end) + ": an inner node without children");
    if (inner > 0 && depth + 1 >= kTreeDepth)
      fail("garbled node stream" + byteAt(w.end) + ": a finest-level voxel has children");
    w.end += 2;
    w.nodes += children;
    return inner;
  });
  return w;
}

void checkEnd(const Walk& w, size_t n, const Header& h) {
  if (w.end < n)
    fail("trailing garbage: " + std::to_string(n - w.end) + (n - w.end == 1 ? " byte" : " bytes") +
         " after the node stream ends" + byteAt(w.end));
  if (w.nodes != h.size)
    fail("garbled: the header says " + std::to_string(h.size) + " nodes, the node stream holds " +
         std::to_string(w.nodes));
}

// The validated node streams, read straight into the compact tree: no OctoMap tree in between,
// so loading a map needs little more memory than the map itself.

// OcTreeBaseImpl::readNodesRecurs: a record (log-odds, then what the type adds), a child mask.
// Attributes are kept on leaves: every one of layerpilot's, a ColorOcTree's color.
void readOtNode(const char*& p, size_t record, CompactOctree& tree, Node& n) {
  std::memcpy(&n.log_odds, p, sizeof(float));
  const auto mask = static_cast<uint8_t>(p[record - 1]);
  if (mask == 0 && record > kOcTreeNodeBytes + 1) {
    Attributes a;
    std::memcpy(&a.color, p + sizeof(float), sizeof(Rgb));
    if (record == kVoxelNodeBytes + 1) {
      std::memcpy(&a.last_seen, p + sizeof(float) + sizeof(Rgb), sizeof(float));
      std::memcpy(&a.min_distance, p + kMinDistanceOffset, sizeof(float));
    }
    if (!(a == Attributes{})) tree.attributes(n) = a;
  }
  p += record;
  for (unsigned i = 0; i < 8; ++i)
    if (mask & (1u << i)) readOtNode(p, record, tree, *tree.createChild(n, i));
}

// OccupancyOcTreeBase::readBinaryNode: leaves get the clamping bounds, inner nodes the maximum
// of their children (the root keeps the upper bound, as OctoMap leaves it).
void readBtNode(const char*& p, CompactOctree& tree, Node& n, float free_log, float occupied_log) {
  const unsigned bits = static_cast<uint8_t>(p[0]) | static_cast<uint8_t>(p[1]) << 8;
  p += 2;
  for (unsigned i = 0; i < 8; ++i) {
    const unsigned code = (bits >> (2 * i)) & 3;
    if (code != 0) tree.createChild(n, i)->log_odds = code == 1 ? free_log : occupied_log;
  }
  for (unsigned i = 0; i < 8; ++i)
    if (((bits >> (2 * i)) & 3) == 3) {
      Node& child = *tree.child(n, i);
      readBtNode(p, tree, child, free_log, occupied_log);
      tree.updateFromChildren(child);
    }
}

// OcTreeBaseImpl::writeNodesRecurs of LayerpilotVoxelTree: data, then one bit per existing child.
// Inner nodes carry a never-hit voxel's attributes (only leaves have any).
void writeOtNode(std::ostream& out, const CompactOctree& tree, const Node& n) {
  const Attributes& a = tree.attributesOf(n);
  out.write(reinterpret_cast<const char*>(&n.log_odds), sizeof(float));
  out.write(reinterpret_cast<const char*>(&a.color), sizeof(Rgb));
  out.write(reinterpret_cast<const char*>(&a.last_seen), sizeof(float));
  out.write(reinterpret_cast<const char*>(&a.min_distance), sizeof(float));
  uint8_t mask = 0;
  for (unsigned i = 0; i < 8; ++i) mask |= uint8_t(tree.child(n, i) != nullptr) << i;
  out.put(static_cast<char>(mask));
  for (unsigned i = 0; i < 8; ++i)
    if (const Node* c = tree.child(n, i)) writeOtNode(out, tree, *c);
}

// OccupancyOcTreeBase::writeBinaryNode: two bits per child (01 free, 10 occupied, 11 inner).
template <class Occupied>
void writeBtNode(std::ostream& out, const CompactOctree& tree, const Node& n, const Occupied& occupied) {
  unsigned bits = 0;
  for (unsigned i = 0; i < 8; ++i)
    if (const Node* c = tree.child(n, i))
      bits |= (CompactOctree::hasChildren(*c) ? 3u : occupied(*c) ? 2u : 1u) << (2 * i);
  out.put(static_cast<char>(bits & 0xff));
  out.put(static_cast<char>(bits >> 8));
  for (unsigned i = 0; i < 8; ++i)
    if (const Node* c = tree.child(n, i); c && CompactOctree::hasChildren(*c)) writeBtNode(out, tree, *c, occupied);
}

}  // namespace

std::string VoxelMap::serialize(FileFormat format) const {
  std::ostringstream out(std::ios::binary);
  std::shared_lock lock(mutex_);
  // OctoMap's headers (AbstractOcTree::write; the .bt one with the stock tree id, so every .bt
  // reader takes the file as is).
  if (format == FileFormat::Ot)
    out << kOtMagic << "\n# (feel free to add / change comments, but leave the first line as it is!)\n#\n"
        << "id LayerpilotVoxelTree\n";
  else
    out << kBtMagic << "\n#\nid OcTree\n";
  out << "size " << tree_.nodeCount() << "\nres " << geometry_.getResolution() << "\ndata\n";
  if (const Node* root = tree_.root()) {
    if (format == FileFormat::Ot)
      writeOtNode(out, tree_, *root);
    else
      writeBtNode(out, tree_, *root, [this](const Node& c) { return occupied(c); });
  }
  if (!out) throw std::runtime_error("cannot serialize the map");
  return out.str();
}

std::unique_ptr<VoxelMap> VoxelMap::parse(const char* data, size_t n, const SensorModel& model) {
  const Header h = parseHeader(data, n);
  const Walk w = h.format == FileFormat::Bt
                     ? walkBt(data, n, h)
                     : walkOt(data, n, h, static_cast<float>(octomap::logodds(model.occupied_threshold)));
  checkEnd(w, n, h);
  auto map = std::make_unique<VoxelMap>(h.res, model);
  if (h.size > 0) {
    const char* p = data + h.data_begin;
    Node& root = *map->tree_.createRoot();
    if (h.format == FileFormat::Bt) {
      const octomap::OcTree stock(h.res);  // a .bt stands for OctoMap's default clamping bounds
      root.log_odds = stock.getClampingThresMaxLog();
      readBtNode(p, map->tree_, root, stock.getClampingThresMinLog(), stock.getClampingThresMaxLog());
    } else {
      readOtNode(p, nodeBytes(h) + 1, map->tree_, root);
    }
    if (p != data + n) throw std::logic_error("the node stream was read differently from its validation");
  }
  map->applyModel();
  map->rebuildColumnIndex();
  return map;
}

}  // namespace layerpilot
