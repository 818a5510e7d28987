#include "unsup_mvs/io/input_limits.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <iterator>
#include <stdexcept>

namespace umvs {

namespace {

std::string mib(uint64_t bytes) { return std::to_string(bytes / kMiB) + " MiB"; }

// CRC-32 (ISO 3309, reflected polynomial 0xEDB88320), as zip stores it.
uint32_t crc32(const char* data, size_t size) {
  static const std::array<uint32_t, 256> table = [] {
    std::array<uint32_t, 256> t{};
    for (uint32_t i = 0; i < 256; ++i) {
      uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[i] = c;
    }
    return t;
  }();
  uint32_t c = 0xFFFFFFFFu;
  for (size_t i = 0; i < size; ++i) c = table[(c ^ static_cast<uint8_t>(data[i])) & 0xFF] ^ (c >> 8);
  return c ^ 0xFFFFFFFFu;
}

// Little-endian fields of a byte buffer; reading past its end throws (a truncated archive).
struct Reader {
  const std::string& bytes;
  const std::string& path;
  [[noreturn]] void fail(const std::string& what) const {
    throw std::runtime_error("'" + path + "' is a damaged model file (zip container: " + what + ")");
  }
  uint64_t get(uint64_t offset, int size) const {
    if (offset > bytes.size() || bytes.size() - offset < static_cast<uint64_t>(size)) fail("truncated");
    uint64_t v = 0;
    for (int i = size - 1; i >= 0; --i) v = (v << 8) | static_cast<uint8_t>(bytes[offset + i]);
    return v;
  }
  uint32_t u32(uint64_t offset) const { return static_cast<uint32_t>(get(offset, 4)); }
  uint16_t u16(uint64_t offset) const { return static_cast<uint16_t>(get(offset, 2)); }
};

}  // namespace

uint64_t checked_file_size(const std::string& path, uint64_t max_bytes, const std::string& what) {
  // Opened without blocking, so that a FIFO or a device is refused instead of waited on.
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK | O_NOCTTY);
  if (fd < 0) throw std::runtime_error("cannot open " + what + " '" + path + "': " + std::strerror(errno));
  struct stat st{};
  const int rc = ::fstat(fd, &st);
  const int stat_errno = errno;
  ::close(fd);
  if (rc != 0) throw std::runtime_error("cannot stat " + what + " '" + path + "': " + std::strerror(stat_errno));
  if (!S_ISREG(st.st_mode)) {
    const char* kind = S_ISDIR(st.st_mode)                          ? "a folder"
                       : S_ISFIFO(st.st_mode)                       ? "a FIFO"
                       : S_ISCHR(st.st_mode) || S_ISBLK(st.st_mode) ? "a device"
                       : S_ISSOCK(st.st_mode)                       ? "a socket"
                                                                    : "not a regular file";
    throw std::runtime_error(what + " '" + path + "' is " + kind + ", not a regular file");
  }
  const uint64_t size = static_cast<uint64_t>(st.st_size);
  if (size > max_bytes) {
    throw std::runtime_error(what + " '" + path + "' is " + std::to_string(size) + " bytes, more than the limit of " +
                             std::to_string(max_bytes) + " (" + mib(max_bytes) + ", docs/reliability.md)");
  }
  return size;
}

std::string read_bounded_file(const std::string& path, uint64_t max_bytes, const std::string& what) {
  const uint64_t size = checked_file_size(path, max_bytes, what);
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot open " + what + " '" + path + "': " + std::strerror(errno));
  std::string bytes(size, '\0');
  in.read(bytes.data(), static_cast<std::streamsize>(size));
  if (static_cast<uint64_t>(in.gcount()) != size) throw std::runtime_error("error while reading " + what + " '" + path + "'");
  return bytes;
}

void check_claimed_count(uint64_t count, uint64_t min_bytes_each, uint64_t available_bytes, const std::string& what) {
  const uint64_t room = min_bytes_each > 0 ? available_bytes / min_bytes_each : UINT64_MAX;
  if (count > room) {
    throw std::runtime_error(what + ": the header claims " + std::to_string(count) + " but the file has room for at most " +
                             std::to_string(room) + " (" + std::to_string(available_bytes) + " bytes left)");
  }
}

void verify_zip_archive(const std::string& bytes, const std::string& path) {
  const Reader r{bytes, path};
  // End of central directory: the last "PK\5\6" within the 64 KiB comment window at the end.
  if (bytes.size() < 22) r.fail("too short");
  uint64_t eocd = bytes.size() - 22;
  const uint64_t lowest = bytes.size() > 22 + 65535 ? bytes.size() - 22 - 65535 : 0;
  while (r.u32(eocd) != 0x06054b50u) {
    if (eocd == lowest) r.fail("no end-of-directory record");
    --eocd;
  }
  uint64_t entries = r.u16(eocd + 10), dir_offset = r.u32(eocd + 16);
  if (entries == 0xFFFF || dir_offset == 0xFFFFFFFFu) {  // zip64: the locator sits just before
    if (eocd < 20 || r.u32(eocd - 20) != 0x07064b50u) r.fail("zip64 locator missing");
    const uint64_t z64 = r.get(eocd - 20 + 8, 8);
    if (r.u32(z64) != 0x06064b50u) r.fail("zip64 end-of-directory record missing");
    entries = r.get(z64 + 32, 8);
    dir_offset = r.get(z64 + 48, 8);
  }
  check_claimed_count(entries, 46, bytes.size(), "'" + path + "': zip directory entries");
  uint64_t pos = dir_offset;
  for (uint64_t e = 0; e < entries; ++e) {
    if (r.u32(pos) != 0x02014b50u) r.fail("directory entry " + std::to_string(e) + " is damaged");
    const uint16_t method = r.u16(pos + 10), name_len = r.u16(pos + 28), extra_len = r.u16(pos + 30);
    const uint32_t crc = r.u32(pos + 16);
    uint64_t compressed = r.u32(pos + 20), uncompressed = r.u32(pos + 24), local = r.u32(pos + 42);
    if (pos + 46 + name_len > bytes.size()) r.fail("truncated directory");
    const std::string name = bytes.substr(pos + 46, name_len);
    // zip64 extended information: 8-byte values for the fields saturated above, in this order.
    for (uint64_t x = pos + 46 + name_len; x + 4 <= pos + 46 + name_len + extra_len;) {
      const uint16_t id = r.u16(x), len = r.u16(x + 2);
      if (id == 0x0001) {
        uint64_t f = x + 4;
        if (uncompressed == 0xFFFFFFFFu) uncompressed = r.get(f, 8), f += 8;
        if (compressed == 0xFFFFFFFFu) compressed = r.get(f, 8), f += 8;
        if (local == 0xFFFFFFFFu) local = r.get(f, 8);
      }
      x += 4 + len;
    }
    if (r.u32(local) != 0x04034b50u) r.fail("entry '" + name + "' has no local header");
    const uint64_t data = local + 30 + r.u16(local + 26) + r.u16(local + 28);
    if (data > bytes.size() || bytes.size() - data < compressed) r.fail("entry '" + name + "' is truncated");
    // Torch stores every entry uncompressed; a compressed one is checked by the inflater when read.
    if (method == 0) {
      if (compressed != uncompressed) r.fail("entry '" + name + "' has inconsistent sizes");
      if (crc32(bytes.data() + data, compressed) != crc) {
        r.fail("entry '" + name + "' fails its CRC-32 check: the file was altered or damaged after it was written");
      }
    }
    pos += 46 + name_len + extra_len + r.u16(pos + 32);
  }
}

bool probe_image_size(const std::string& path, int* width, int* height) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  std::string head(64 * 1024, '\0');
  in.read(head.data(), static_cast<std::streamsize>(head.size()));
  head.resize(static_cast<size_t>(in.gcount()));
  return probe_image_header(head, width, height);
}

bool probe_image_header(const std::string& head, int* width, int* height) {
  auto be = [&](size_t at, int size) -> uint64_t {
    uint64_t v = 0;
    for (int i = 0; i < size; ++i) v = (v << 8) | static_cast<uint8_t>(head[at + i]);
    return v;
  };
  if (head.size() >= 24 && head.compare(0, 8, "\x89PNG\r\n\x1a\n") == 0 && head.compare(12, 4, "IHDR") == 0) {
    *width = static_cast<int>(std::min<uint64_t>(be(16, 4), INT32_MAX));
    *height = static_cast<int>(std::min<uint64_t>(be(20, 4), INT32_MAX));
    return true;
  }
  if (head.size() < 4 || static_cast<uint8_t>(head[0]) != 0xFF || static_cast<uint8_t>(head[1]) != 0xD8) return false;
  // JPEG: walk the marker segments to the first start-of-frame (SOF0..SOF15 except DHT, JPG, DAC).
  size_t pos = 2;
  while (pos + 9 <= head.size()) {
    if (static_cast<uint8_t>(head[pos]) != 0xFF) return false;
    const uint8_t marker = static_cast<uint8_t>(head[pos + 1]);
    if (marker == 0xFF) {
      ++pos;
      continue;
    }
    const bool sof = marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
    if (sof) {
      *height = static_cast<int>(be(pos + 5, 2));
      *width = static_cast<int>(be(pos + 7, 2));
      return true;
    }
    pos += 2 + be(pos + 2, 2);
  }
  return false;
}

void check_image_pixels(int64_t width, int64_t height, const std::string& what) {
  if (width > 0 && height > 0 && width * height > kMaxImagePixels) {
    throw std::runtime_error(what + " is " + std::to_string(width) + "x" + std::to_string(height) + " = " +
                             std::to_string(width * height / 1000000) + " megapixels, more than the " +
                             std::to_string(kMaxImagePixels / 1000000) +
                             " megapixels this program accepts (docs/reliability.md)");
  }
}

}  // namespace umvs
