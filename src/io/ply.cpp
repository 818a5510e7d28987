#include "unsup_mvs/io/ply.h"

#include <cstdlib>
#include <cstring>
#include <sstream>
#include <stdexcept>

#include "unsup_mvs/io/atomic_file.h"
#include "unsup_mvs/io/input_limits.h"

namespace umvs {

void write_ply(const std::string& path, const PointCloud& cloud) {
  const size_t n = cloud.size();
  const bool rgb = cloud.colors.size() == n && n > 0;
  const bool conf = cloud.confidence.size() == n && n > 0;
  const bool views = cloud.num_views.size() == n && n > 0;
  write_file_atomically(path, [&](std::ostream& out) {
    out << "ply\nformat binary_little_endian 1.0\ncomment written by unsup_mvs\n"
        << "element vertex " << n << "\nproperty float x\nproperty float y\nproperty float z\n";
    if (rgb) out << "property uchar red\nproperty uchar green\nproperty uchar blue\n";
    if (conf) out << "property float confidence\n";
    if (views) out << "property uchar views\n";
    out << "end_header\n";
    std::string record;
    for (size_t i = 0; i < n; ++i) {
      record.clear();
      record.append(reinterpret_cast<const char*>(cloud.points[i].data()), 12);
      if (rgb) record.append(reinterpret_cast<const char*>(cloud.colors[i].data()), 3);
      if (conf) record.append(reinterpret_cast<const char*>(&cloud.confidence[i]), 4);
      if (views) record.push_back(static_cast<char>(cloud.num_views[i]));
      out.write(record.data(), static_cast<std::streamsize>(record.size()));
    }
  });
}

namespace {
struct Property {
  std::string name, type;
  size_t size() const {
    if (type == "char" || type == "uchar" || type == "int8" || type == "uint8") return 1;
    if (type == "short" || type == "ushort" || type == "int16" || type == "uint16") return 2;
    if (type == "double" || type == "float64") return 8;
    return 4;
  }
  double read(const char* p) const {
    if (type == "float" || type == "float32") { float v; std::memcpy(&v, p, 4); return v; }
    if (type == "double" || type == "float64") { double v; std::memcpy(&v, p, 8); return v; }
    if (type == "uchar" || type == "uint8") return static_cast<unsigned char>(*p);
    if (type == "char" || type == "int8") return static_cast<signed char>(*p);
    if (type == "short" || type == "int16") { int16_t v; std::memcpy(&v, p, 2); return v; }
    if (type == "ushort" || type == "uint16") { uint16_t v; std::memcpy(&v, p, 2); return v; }
    if (type == "int" || type == "int32") { int32_t v; std::memcpy(&v, p, 4); return v; }
    uint32_t v; std::memcpy(&v, p, 4); return v;
  }
};
}  // namespace

PointCloud read_ply(const std::string& path) {
  const std::string bytes = read_bounded_file(path, kMaxPlyBytes, "PLY file");
  auto fail = [&](const std::string& what) { throw std::runtime_error("'" + path + "': " + what); };
  const size_t end = bytes.find("end_header");
  if (bytes.compare(0, 3, "ply") != 0 || end == std::string::npos) fail("not a PLY file");
  std::istringstream header(bytes.substr(0, end));
  std::string line, format;
  size_t vertex_count = 0;
  bool in_vertex = false, vertex_seen = false;
  std::vector<Property> props;
  while (std::getline(header, line)) {
    std::istringstream ls(line);
    std::string key;
    ls >> key;
    if (key == "format") {
      ls >> format;
    } else if (key == "element") {
      std::string name, count_text;
      ls >> name >> count_text;
      if (count_text.empty() || count_text.find_first_not_of("0123456789") != std::string::npos || count_text.size() > 18) {
        fail("malformed element line '" + line + "'");
      }
      const size_t count = std::stoull(count_text);
      if (vertex_seen && !in_vertex) continue;
      in_vertex = name == "vertex";
      if (in_vertex) { vertex_count = count; vertex_seen = true; }
      else if (!vertex_seen) fail("elements before 'vertex' are not supported");
    } else if (key == "property" && in_vertex) {
      Property p;
      ls >> p.type;
      if (p.type == "list") fail("list properties on vertices are not supported");
      ls >> p.name;
      props.push_back(p);
    }
  }
  if (!vertex_seen) fail("no vertex element");
  auto index_of = [&](const std::string& name) {
    for (size_t i = 0; i < props.size(); ++i) if (props[i].name == name) return static_cast<int>(i);
    return -1;
  };
  const int ix = index_of("x"), iy = index_of("y"), iz = index_of("z");
  const int ir = index_of("red"), ig = index_of("green"), ib = index_of("blue");
  const int ic = index_of("confidence"), iv = index_of("views");
  if (ix < 0 || iy < 0 || iz < 0) fail("vertices have no x/y/z");
  const size_t header_end = bytes.find('\n', end);
  if (header_end == std::string::npos) fail("no vertex data after end_header");
  const size_t pos = header_end + 1;
  size_t stride = 0;
  for (const auto& p : props) stride += p.size();
  // The claimed count must fit in the file before anything is allocated for it: a binary vertex
  // takes `stride` bytes, an ASCII one at least a digit and a separator per property.
  check_claimed_count(vertex_count, format == "ascii" ? 2 * props.size() : stride, bytes.size() - pos,
                      "'" + path + "': vertex count");
  PointCloud cloud;
  cloud.points.resize(vertex_count);
  const bool rgb = ir >= 0 && ig >= 0 && ib >= 0;
  if (rgb) cloud.colors.resize(vertex_count);
  if (ic >= 0) cloud.confidence.resize(vertex_count);
  if (iv >= 0) cloud.num_views.resize(vertex_count);
  std::vector<double> values(props.size());
  auto store = [&](size_t i) {
    cloud.points[i] = Eigen::Vector3f(values[ix], values[iy], values[iz]);
    if (!cloud.points[i].allFinite()) fail("vertex " + std::to_string(i) + " has a non-finite coordinate (NaN or infinity)");
    if (rgb) cloud.colors[i] = {static_cast<uint8_t>(values[ir]), static_cast<uint8_t>(values[ig]), static_cast<uint8_t>(values[ib])};
    if (ic >= 0) cloud.confidence[i] = static_cast<float>(values[ic]);
    if (iv >= 0) cloud.num_views[i] = static_cast<uint8_t>(values[iv]);
  };
  if (format == "ascii") {
    // strtod, unlike operator>>, reads "nan" and "inf", so that they are reported as such.
    const char* cursor = bytes.c_str() + pos;
    for (size_t i = 0; i < vertex_count; ++i) {
      for (auto& v : values) {
        char* next = nullptr;
        v = std::strtod(cursor, &next);
        if (next == cursor) fail("truncated or malformed vertex data at vertex " + std::to_string(i));
        cursor = next;
      }
      store(i);
    }
  } else if (format == "binary_little_endian") {
    if (bytes.size() - pos < stride * vertex_count) fail("truncated vertex data");
    for (size_t i = 0; i < vertex_count; ++i) {
      const char* rec = bytes.data() + pos + i * stride;
      size_t off = 0;
      for (size_t k = 0; k < props.size(); ++k) { values[k] = props[k].read(rec + off); off += props[k].size(); }
      store(i);
    }
  } else {
    fail("unsupported PLY format '" + format + "'");
  }
  return cloud;
}

}  // namespace umvs
