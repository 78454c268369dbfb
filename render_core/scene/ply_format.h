// Internal: the parts of the PLY format (header, element tables) shared by the readers and writers.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace catgs::ply {

enum class Type { i8, u8, i16, u16, i32, u32, f32, f64 };

// Parses a PLY type name (char/int8, uchar/uint8, ..., float/float32, double/float64).
bool parse_type(const std::string& name, Type* type);
int type_size(Type type);

struct Property {
  std::string name;
  Type type;
  std::size_t offset = 0;  // byte offset in a binary row
};

struct Element {
  std::string name;
  uint64_t count = 0;
  std::vector<Property> properties;
  std::size_t row_size = 0;        // bytes per row (binary)
  std::size_t data_offset = 0;     // byte offset of the first row in the file (binary)
  std::vector<double> ascii_rows;  // [count, properties] (ascii only)

  // Index of a property by name, or -1.
  int find(const std::string& property) const;
};

// A read-only memory map of a whole file (POSIX mmap), unmapped on destruction. Its pages are the
// page cache's, not the process's own memory, and release() hands a range back, so a reader
// that walks the rows once holds only the rows it is on (peak memory ~ the model it builds, not
// the model plus the file).
class MappedFile {
 public:
  MappedFile() = default;
  // Throws SceneFileError naming `path` when it cannot be opened or mapped.
  MappedFile(const std::string& path, uint64_t size);
  ~MappedFile();
  MappedFile(MappedFile&& other) noexcept;
  MappedFile& operator=(MappedFile&& other) noexcept;
  MappedFile(const MappedFile&) = delete;
  MappedFile& operator=(const MappedFile&) = delete;

  const uint8_t* data() const { return data_; }
  uint64_t size() const { return size_; }
  // Drops the whole pages inside [begin, end) from this process's memory (madvise DONTNEED: a
  // later read maps them again from the file, so nothing is lost, only re-read).
  void release(uint64_t begin, uint64_t end) const;

 private:
  const uint8_t* data_ = nullptr;
  uint64_t size_ = 0;
};

// A parsed PLY file: header and access to every value as double.
struct File {
  std::string path;
  bool ascii = false;
  std::vector<Element> elements;
  MappedFile bytes;  // the whole file, mapped (binary)

  const Element* element(const std::string& name) const;
  double value(const Element& e, uint64_t row, int property) const;
  // Rows [0, rows) of `e` will not be read again: their whole pages leave this process's memory
  // (binary files; a no-op for ascii ones, parsed up front).
  void release_rows(const Element& e, uint64_t rows) const { release_rows(e, 0, rows); }
  // The same for rows [begin, end) (a block of a parallel load; load_blocks.h).
  void release_rows(const Element& e, uint64_t begin, uint64_t end) const;
};

// Reads and validates a PLY file. Throws SceneFileError naming the path.
File read_file(const std::string& path);

}  // namespace catgs::ply
