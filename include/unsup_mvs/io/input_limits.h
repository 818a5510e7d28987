// What one command-line call accepts as input, and the checks made before a file is read, so that
// a broken or hostile file gets a clear error instead of a hang (a FIFO), an unbounded read
// (/dev/zero), a giant allocation (a header that claims 5e8 points) or silent corruption (a
// checkpoint with a flipped byte). The bounds are listed in docs/reliability.md, "Resource bounds
// (command line)".
#pragma once

#include <cstdint>
#include <string>

namespace umvs {

constexpr uint64_t kMiB = uint64_t{1} << 20;
constexpr uint64_t kMaxCheckpointBytes = 512 * kMiB;  // ours: 4 MB with Adam state; MVSNet_pytorch: 1.4 MB
constexpr uint64_t kMaxArrayFileBytes = 2048 * kMiB;  // one PFM or NPY file
constexpr uint64_t kMaxPlyBytes = 4096 * kMiB;        // one PLY cloud (about 270 M points of 15 bytes)
constexpr uint64_t kMaxImageFileBytes = 512 * kMiB;   // one encoded image
constexpr uint64_t kMaxTextFileBytes = 256 * kMiB;    // a cam file or pair.txt
constexpr int64_t kMaxImagePixels = int64_t{64} << 20;  // 8192 x 8192: 192 MiB as RGB8, 768 MiB as float

// Size of the regular file at `path` (links are followed). Opens it without blocking, so a FIFO or
// a device is refused instead of waited on. Throws std::runtime_error naming `what` and the path
// when it is missing, unreadable, not a regular file (a FIFO, a device, a folder) or larger than
// `max_bytes`. Every reader of user files checks with this first.
uint64_t checked_file_size(const std::string& path, uint64_t max_bytes, const std::string& what);

// The whole file, after checked_file_size.
std::string read_bounded_file(const std::string& path, uint64_t max_bytes, const std::string& what);

// A count claimed by a file's header must fit in the bytes that follow it: throws
// std::runtime_error "<what>: the header claims <count> ... but the file has room for at most N"
// when count * min_bytes_each > available_bytes (without overflowing).
void check_claimed_count(uint64_t count, uint64_t min_bytes_each, uint64_t available_bytes, const std::string& what);

// Verifies a zip archive in memory (torch's checkpoint container; LibTorch's reader skips the
// checksums): the central directory is readable and every entry's data is inside the file, stored
// (not compressed) and matches its CRC-32. Throws std::runtime_error naming `path` and the entry.
void verify_zip_archive(const std::string& bytes, const std::string& path);

// Width and height from a PNG or JPEG header without decoding the image; false when the file is
// neither (or its header is unreadable: the decoder then reports it).
bool probe_image_size(const std::string& path, int* width, int* height);
// The same for the first bytes of an encoded image in memory (a CompressedImage's data).
bool probe_image_header(const std::string& head, int* width, int* height);

// Throws std::runtime_error naming `what` when width x height exceeds kMaxImagePixels.
void check_image_pixels(int64_t width, int64_t height, const std::string& what);

}  // namespace umvs
