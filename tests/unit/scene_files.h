// Helpers for tests that write crafted scene files and check the loader's errors.
#pragma once

#include <string>

namespace catgs::test {

// The bytes of the file at `path` ("" when it cannot be read).
std::string read_bytes(const std::string& path);
// Writes `bytes` to `path`, replacing it.
void write_bytes(const std::string& path, const std::string& bytes);
// Replaces the first occurrence of `from` in the header of `bytes` (a test failure when absent).
std::string replace_in_header(std::string bytes, const std::string& from, const std::string& to);
// Expects load_scene(path) to throw SceneFileError whose message names the file and `problem`.
void expect_scene_error(const std::string& path, const std::string& problem);

}  // namespace catgs::test
