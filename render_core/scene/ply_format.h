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

// A parsed PLY file: header and access to every value as double.
struct File {
  std::string path;
  bool ascii = false;
  std::vector<Element> elements;
  std::vector<uint8_t> bytes;  // the whole file (binary)

  const Element* element(const std::string& name) const;
  double value(const Element& e, uint64_t row, int property) const;
};

// Reads and validates a PLY file. Throws SceneFileError naming the path.
File read_file(const std::string& path);

}  // namespace catgs::ply
