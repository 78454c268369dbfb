// Writing our own derived files (scene caches, compact scenes) so that a reader never maps half a
// file: through a temporary file beside the target, renamed into place.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

namespace catgs {

// Creates `path`.tmp.PID sized to `size` bytes, calls fill(fd) to write it (pwrite, from any
// thread), closes it and renames it over `path`. Whatever fill throws, and every failure here
// (SceneFileError naming `path`: cannot create, size, close or rename), removes the temporary.
void write_replacing(const std::string& path, uint64_t size, const std::function<void(int fd)>& fill);

// pwrite of all `bytes` at `offset`, retried until done. Throws SceneFileError naming `path`.
void write_all(int fd, const void* data, uint64_t bytes, uint64_t offset, const std::string& path);

}  // namespace catgs
