// Writing only where we were told to and never through a planted link: containment checks,
// exclusive temporary files, publishing under a new name only, reading only regular files of a
// bounded size, and removing the temporary files an interrupted write left behind.
#pragma once

#include <cstdint>
#include <string>

namespace umvs {

// Temporary files are named "<target>.tmp-<random>" beside their target.
constexpr char kTempInfix[] = ".tmp-";

// Creates and opens (O_CREAT|O_EXCL, so never through an existing name or link) a new file named
// "<path>.tmp-XXXXXX" in `path`'s folder. Returns its name; *fd is the open descriptor.
// Throws std::runtime_error naming `path`.
std::string create_temp_file_beside(const std::string& path, int* fd);

// Copies `from` to `to`, which must not exist (not even as a symlink): written to a temporary file
// beside `to`, then linked under the final name, which fails instead of replacing anything that
// appeared meanwhile. Throws std::runtime_error naming the file; nothing is left behind on failure.
void copy_file_to_new_name(const std::string& from, const std::string& to);

// True when `path` (which need not exist) lies strictly inside `dir` after resolving '..' and links.
bool path_inside(const std::string& path, const std::string& dir);

// The path a request for `requested` means inside `dir`: a relative path is taken relative to
// `dir`; the result must lie inside `dir` after resolving '..' and links. Throws
// std::invalid_argument saying why it is refused.
std::string resolve_inside(const std::string& dir, const std::string& requested);


// Removes the "*.tmp-*" files that interrupted writes left in `dir` and its sub-folders (links to
// folders are not followed). Only call it when no writer can be active there. Returns the count.
int remove_stale_temp_files(const std::string& dir);

}  // namespace umvs
