#include "unsup_mvs/io/array_io.h"

#include <torch/torch.h>

#include <cstring>
#include <regex>
#include <sstream>
#include <stdexcept>

#include "unsup_mvs/io/atomic_file.h"
#include "unsup_mvs/io/input_limits.h"

namespace umvs {

namespace {

struct DtypeInfo {
  const char* descr;
  torch::ScalarType type;
  size_t size;
};
const DtypeInfo kDtypes[] = {{"<f4", torch::kFloat32, 4}, {"<f8", torch::kFloat64, 8},
                             {"|u1", torch::kUInt8, 1},   {"<i4", torch::kInt32, 4},
                             {"<i8", torch::kInt64, 8}};

[[noreturn]] void fail(const std::string& path, const std::string& what) {
  throw std::runtime_error("'" + path + "': " + what);
}

}  // namespace

torch::Tensor read_npy(const std::string& path) {
  const std::string bytes = read_bounded_file(path, kMaxArrayFileBytes, ".npy file");
  if (bytes.size() < 10 || bytes.compare(0, 6, "\x93NUMPY") != 0) fail(path, "not a .npy file (bad magic)");
  const int major = static_cast<unsigned char>(bytes[6]);
  size_t header_len = 0, offset = 0;
  if (major == 1) {
    header_len = static_cast<unsigned char>(bytes[8]) | (static_cast<unsigned char>(bytes[9]) << 8);
    offset = 10;
  } else if (major == 2 || major == 3) {
    if (bytes.size() < 12) fail(path, "truncated header");
    uint32_t len;
    std::memcpy(&len, bytes.data() + 8, 4);
    header_len = len;
    offset = 12;
  } else {
    fail(path, "unsupported .npy version " + std::to_string(major));
  }
  if (offset + header_len > bytes.size()) fail(path, "truncated header");
  const std::string header = bytes.substr(offset, header_len);
  std::smatch m;
  if (!std::regex_search(header, m, std::regex("'descr':\\s*'([^']+)'"))) fail(path, "no dtype in header");
  const std::string descr = m[1];
  if (std::regex_search(header, std::regex("'fortran_order':\\s*True"))) fail(path, "Fortran order is not supported");
  if (!std::regex_search(header, m, std::regex("'shape':\\s*\\(([^)]*)\\)"))) fail(path, "no shape in header");
  std::vector<int64_t> shape;
  const std::string dims = m[1];
  std::regex num("\\d+");
  // Each dimension, and their product, must fit in the data that follows the header (checked
  // one dimension at a time, so that the product cannot overflow).
  const size_t data_offset = offset + header_len;
  uint64_t count = 1;
  for (auto it = std::sregex_iterator(dims.begin(), dims.end(), num); it != std::sregex_iterator(); ++it) {
    if (it->str().size() > 18) fail(path, "dimension " + it->str() + " in the header is too large");
    const uint64_t dim = std::stoull(it->str());
    // dim * count <= bytes left, as dim <= bytes left / count.
    if (count > 0) check_claimed_count(dim, count, bytes.size() - data_offset, "'" + path + "': array dimension");
    count *= dim;
    shape.push_back(static_cast<int64_t>(dim));
  }
  const DtypeInfo* info = nullptr;
  for (const auto& d : kDtypes) {
    if (descr == d.descr || (d.size == 1 && descr == "<u1")) info = &d;
  }
  if (!info) fail(path, "unsupported dtype '" + descr + "' (float32/64, uint8, int32/64 little-endian)");
  check_claimed_count(count, info->size, bytes.size() - data_offset, "'" + path + "': array elements");
  auto out = torch::empty(shape, info->type);
  std::memcpy(out.data_ptr(), bytes.data() + data_offset, count * info->size);
  return out;
}

void write_npy(const std::string& path, const torch::Tensor& tensor) {
  auto t = tensor.detach().to(torch::kCPU).contiguous();
  const DtypeInfo* info = nullptr;
  for (const auto& d : kDtypes) {
    if (d.type == t.scalar_type()) info = &d;
  }
  if (!info) throw std::invalid_argument("write_npy: unsupported dtype " + std::string(c10::toString(t.scalar_type())));
  std::ostringstream shape;
  shape << "(";
  for (int64_t i = 0; i < t.dim(); ++i) shape << t.size(i) << (t.dim() == 1 || i + 1 < t.dim() ? "," : "");
  shape << ")";
  std::string header = std::string("{'descr': '") + info->descr + "', 'fortran_order': False, 'shape': " + shape.str() + ", }";
  const size_t total = 10 + header.size() + 1;
  header.append((64 - total % 64) % 64, ' ');
  header.push_back('\n');
  write_file_atomically(path, [&](std::ostream& out) {
    out.write("\x93NUMPY\x01\x00", 8);
    const uint16_t len = static_cast<uint16_t>(header.size());
    out.put(static_cast<char>(len & 0xff));
    out.put(static_cast<char>(len >> 8));
    out << header;
    out.write(static_cast<const char*>(t.data_ptr()), t.numel() * info->size);
  });
}

torch::Tensor read_pfm(const std::string& path) {
  const std::string bytes = read_bounded_file(path, kMaxArrayFileBytes, "PFM file");
  std::istringstream in(bytes);
  std::string magic;
  int width = 0, height = 0;
  double scale = 0;
  in >> magic >> width >> height >> scale;
  if (!in || (magic != "Pf" && magic != "PF")) fail(path, "not a PFM file");
  if (width <= 0 || height <= 0) fail(path, "bad PFM size");
  in.get();  // the single whitespace after the scale
  const int channels = magic == "PF" ? 3 : 1;
  const size_t offset = static_cast<size_t>(in.tellg());
  const size_t count = static_cast<size_t>(width) * height * channels;
  if (!in || offset > bytes.size()) fail(path, "truncated PFM header");
  check_claimed_count(count, 4, bytes.size() - offset, "'" + path + "': PFM values");
  auto img = torch::empty({height, width, channels}, torch::kFloat32);
  std::memcpy(img.data_ptr(), bytes.data() + offset, count * 4);
  if (scale > 0) {  // big-endian data
    auto* p = reinterpret_cast<uint32_t*>(img.data_ptr());
    for (size_t i = 0; i < count; ++i) p[i] = __builtin_bswap32(p[i]);
  }
  img = img.flip(0).contiguous();  // PFM rows go bottom to top
  return channels == 1 ? img.squeeze(2) : img;
}

void write_pfm(const std::string& path, const torch::Tensor& image) {
  auto t = image.detach().to(torch::kCPU, torch::kFloat32);
  if (!(t.dim() == 2 || (t.dim() == 3 && t.size(2) == 3))) {
    throw std::invalid_argument("write_pfm: expected [H,W] or [H,W,3], got " + std::string(c10::str(t.sizes())));
  }
  const bool colour = t.dim() == 3;
  t = t.flip(0).contiguous();
  write_file_atomically(path, [&](std::ostream& out) {
    out << (colour ? "PF" : "Pf") << "\n" << t.size(1) << " " << t.size(0) << "\n-1\n";
    out.write(static_cast<const char*>(t.data_ptr()), t.numel() * 4);
  });
}

}  // namespace umvs
