#include "scene_files.h"

#include <fstream>
#include <iterator>

#include <gtest/gtest.h>

#include "scene/ply_io.h"

namespace catgs::test {

std::string read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void write_bytes(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
}

std::string replace_in_header(std::string bytes, const std::string& from, const std::string& to) {
  const auto end = bytes.find("end_header");
  const auto at = bytes.find(from);
  EXPECT_TRUE(at != std::string::npos && at < end) << "header lacks '" << from << "'";
  if (at == std::string::npos) return bytes;
  return bytes.replace(at, from.size(), to);
}

void expect_scene_error(const std::string& path, const std::string& problem) {
  try {
    load_scene(path);
    ADD_FAILURE() << "loading " << path << " should fail with '" << problem << "'";
  } catch (const SceneFileError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(path), std::string::npos) << what;
    EXPECT_NE(what.find(problem), std::string::npos) << what;
  }
}

}  // namespace catgs::test
