// Replacing writes of derived files (file_write.h).
#include "scene/file_write.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "scene/gaussian_model.h"

namespace catgs {

void write_replacing(const std::string& path, uint64_t size, const std::function<void(int fd)>& fill) {
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw SceneFileError(path, std::string("cannot create: ") + std::strerror(errno));
  try {
    if (::ftruncate(fd, static_cast<off_t>(size)) != 0)
      throw SceneFileError(path, std::string("cannot size: ") + std::strerror(errno));
    fill(fd);
    if (::close(fd) != 0) throw SceneFileError(path, std::string("cannot close: ") + std::strerror(errno));
  } catch (...) {
    ::close(fd);
    ::unlink(tmp.c_str());
    throw;
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    const int e = errno;
    ::unlink(tmp.c_str());
    throw SceneFileError(path, std::string("cannot rename the written file into place: ") + std::strerror(e));
  }
}

void write_all(int fd, const void* data, uint64_t bytes, uint64_t offset, const std::string& path) {
  const auto* p = static_cast<const char*>(data);
  while (bytes > 0) {
    const ssize_t w = ::pwrite(fd, p, bytes, static_cast<off_t>(offset));
    if (w <= 0) throw SceneFileError(path, std::string("cannot write: ") + std::strerror(errno));
    p += w;
    bytes -= static_cast<uint64_t>(w);
    offset += static_cast<uint64_t>(w);
  }
}

}  // namespace catgs
