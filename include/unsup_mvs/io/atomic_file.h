// Writing files so that a reader never sees half a file and a failed write never destroys the
// previous good file: write to a new "<path>.tmp-XXXXXX" in the same folder (created exclusively,
// so never through a planted link; see file_safety.h), flush, then rename over `path`.
#pragma once

#include <functional>
#include <ostream>
#include <string>

namespace umvs {

// Calls `write` with a binary stream; on success renames the temporary file over `path`.
// On any failure (exception from `write`, stream error) removes the temporary file and throws
// std::runtime_error naming the path; an existing file at `path` is left untouched. A symlink or
// anything else that is not a regular file at `path` is refused, never followed or replaced.
void write_file_atomically(const std::string& path, const std::function<void(std::ostream&)>& write);

// Creates the folder and its parents; throws std::runtime_error naming the folder on failure.
void make_directories(const std::string& path);

std::string read_file_bytes(const std::string& path);  // throws std::runtime_error naming the path

}  // namespace umvs
