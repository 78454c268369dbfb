// PLY header and body parsing with size checks done before any allocation a header could inflate.
#include "ply_format.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>
#include <utility>

#include "scene/gaussian_model.h"

namespace catgs::ply {

namespace {
constexpr std::size_t kMaxHeaderBytes = 1 << 20;

// a * b and a + b, or false when the result would not fit 64 bits (a header's counts are
// attacker-controlled: a wrapped product would size a buffer smaller than the rows written to it).
bool checked_mul(uint64_t a, uint64_t b, uint64_t* out) { return !__builtin_mul_overflow(a, b, out); }
bool checked_add(uint64_t a, uint64_t b, uint64_t* out) { return !__builtin_add_overflow(a, b, out); }
}  // namespace

bool parse_type(const std::string& n, Type* t) {
  if (n == "char" || n == "int8")
    *t = Type::i8;
  else if (n == "uchar" || n == "uint8")
    *t = Type::u8;
  else if (n == "short" || n == "int16")
    *t = Type::i16;
  else if (n == "ushort" || n == "uint16")
    *t = Type::u16;
  else if (n == "int" || n == "int32")
    *t = Type::i32;
  else if (n == "uint" || n == "uint32")
    *t = Type::u32;
  else if (n == "float" || n == "float32")
    *t = Type::f32;
  else if (n == "double" || n == "float64")
    *t = Type::f64;
  else
    return false;
  return true;
}

int type_size(Type t) {
  switch (t) {
    case Type::i8:
    case Type::u8:
      return 1;
    case Type::i16:
    case Type::u16:
      return 2;
    case Type::i32:
    case Type::u32:
    case Type::f32:
      return 4;
    case Type::f64:
      return 8;
  }
  return 0;
}

int Element::find(const std::string& property) const {
  for (std::size_t i = 0; i < properties.size(); ++i)
    if (properties[i].name == property) return static_cast<int>(i);
  return -1;
}

const Element* File::element(const std::string& name) const {
  for (const auto& e : elements)
    if (e.name == name) return &e;
  return nullptr;
}

MappedFile::MappedFile(const std::string& path, uint64_t size) : size_(size) {
  if (size == 0) return;
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw SceneFileError(path, std::string("cannot open file: ") + std::strerror(errno));
  void* p = ::mmap(nullptr, size, PROT_READ, MAP_PRIVATE, fd, 0);
  const int map_errno = errno;
  ::close(fd);  // the mapping keeps the file
  if (p == MAP_FAILED) throw SceneFileError(path, std::string("cannot map file: ") + std::strerror(map_errno));
  ::madvise(p, size, MADV_SEQUENTIAL);  // read ahead, drop behind: the loaders walk it once
  data_ = static_cast<const uint8_t*>(p);
}

MappedFile::~MappedFile() {
  if (data_) ::munmap(const_cast<uint8_t*>(data_), size_);
}

MappedFile::MappedFile(MappedFile&& other) noexcept
    : data_(std::exchange(other.data_, nullptr)), size_(std::exchange(other.size_, 0)) {}

MappedFile& MappedFile::operator=(MappedFile&& other) noexcept {
  if (this != &other) {
    if (data_) ::munmap(const_cast<uint8_t*>(data_), size_);
    data_ = std::exchange(other.data_, nullptr);
    size_ = std::exchange(other.size_, 0);
  }
  return *this;
}

void MappedFile::release(uint64_t begin, uint64_t end) const {
  const auto page = static_cast<uint64_t>(::sysconf(_SC_PAGESIZE));
  begin = (begin + page - 1) / page * page;  // whole pages only: neighbours may still be read
  end = std::min(end, size_) / page * page;
  if (!data_ || begin >= end) return;
  ::madvise(const_cast<uint8_t*>(data_) + begin, end - begin, MADV_DONTNEED);
}

void File::release_rows(const Element& e, uint64_t begin, uint64_t end) const {
  if (!ascii) bytes.release(e.data_offset + begin * e.row_size, e.data_offset + end * e.row_size);
}

double File::value(const Element& e, uint64_t row, int property) const {
  if (ascii) return e.ascii_rows[row * e.properties.size() + static_cast<std::size_t>(property)];
  const Property& p = e.properties[static_cast<std::size_t>(property)];
  const uint8_t* at = bytes.data() + e.data_offset + row * e.row_size + p.offset;
  auto load = [at](auto v) {
    std::memcpy(&v, at, sizeof v);
    return static_cast<double>(v);
  };
  switch (p.type) {
    case Type::i8:
      return load(int8_t{});
    case Type::u8:
      return load(uint8_t{});
    case Type::i16:
      return load(int16_t{});
    case Type::u16:
      return load(uint16_t{});
    case Type::i32:
      return load(int32_t{});
    case Type::u32:
      return load(uint32_t{});
    case Type::f32:
      return load(float{});
    case Type::f64:
      return load(double{});
  }
  return 0.0;
}

namespace {

[[noreturn]] void fail(const std::string& path, const std::string& problem) { throw SceneFileError(path, problem); }

// The header's text: lines up to and including "end_header\n" (at most kMaxHeaderBytes).
std::string read_header_text(std::istream& in, const std::string& path) {
  std::string header, line;
  bool ended = false;
  while (header.size() < kMaxHeaderBytes && std::getline(in, line)) {
    // getline stops at the end of the file too: a last line without '\n' would make the header
    // one byte longer than the file, and the body offset would point past its end.
    if (in.eof()) {
      if (line == "end_header" || line == "end_header\r") fail(path, "no newline after end_header");
      break;
    }
    header += line + "\n";
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line == "end_header") {
      ended = true;
      break;
    }
  }
  if (header.rfind("ply", 0) != 0) fail(path, "not a PLY file (no 'ply' magic line)");
  if (!ended) fail(path, "PLY header has no end_header line");
  return header;
}

// One "element NAME COUNT" or "property TYPE NAME" line into `f`.
void parse_element(std::istringstream& ls, const std::string& where, File& f) {
  Element e;
  std::string count;
  ls >> e.name >> count;
  uint64_t n = 0;
  const auto res = std::from_chars(count.data(), count.data() + count.size(), n);
  if (e.name.empty() || res.ec != std::errc() || res.ptr != count.data() + count.size())
    fail(f.path, "malformed element count in " + where);
  if (f.element(e.name)) fail(f.path, "duplicate element '" + e.name + "' in " + where);
  e.count = n;
  f.elements.push_back(std::move(e));
}

void parse_property(std::istringstream& ls, const std::string& where, File& f) {
  if (f.elements.empty()) fail(f.path, "property before any element in " + where);
  std::string type, name;
  ls >> type >> name;
  if (type == "list") fail(f.path, "list properties are not supported (" + where + ")");
  Property p;
  p.name = name;
  if (name.empty() || !parse_type(type, &p.type)) fail(f.path, "bad property in " + where);
  Element& e = f.elements.back();
  if (e.find(name) >= 0) fail(f.path, "duplicate property '" + name + "' in element " + e.name);
  p.offset = e.row_size;
  e.row_size += static_cast<std::size_t>(type_size(p.type));
  e.properties.push_back(p);
}

// The header's format, elements and properties into `f`.
void parse_header(const std::string& header, File& f) {
  std::istringstream hs(header);
  std::string line;
  bool have_format = false;
  int line_no = 0;
  while (std::getline(hs, line)) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::istringstream ls(line);
    std::string word;
    ls >> word;
    const std::string where = "header line " + std::to_string(line_no) + " '" + line + "'";
    if (word == "ply" || word == "comment" || word == "obj_info" || word == "end_header" || word.empty()) continue;
    if (word == "format") {
      std::string fmt;
      ls >> fmt;
      if (fmt == "binary_little_endian")
        f.ascii = false;
      else if (fmt == "ascii")
        f.ascii = true;
      else
        fail(f.path, "unsupported PLY format '" + fmt + "' (binary_little_endian or ascii only)");
      have_format = true;
    } else if (word == "element") {
      parse_element(ls, where, f);
    } else if (word == "property") {
      parse_property(ls, where, f);
    } else {
      fail(f.path, "unknown header keyword in " + where);
    }
  }
  if (!have_format) fail(f.path, "PLY header has no format line");
}

// A binary body: sizes checked against the file before allocating anything a header count could
// inflate, then the whole file mapped into f.bytes.
void read_binary_body(uint64_t file_size, uint64_t body_offset, File& f) {
  // Invariant: at <= file_size, so file_size - at never wraps.
  uint64_t at = body_offset;
  for (auto& e : f.elements) {
    if (e.row_size == 0 && e.count > 0) fail(f.path, "element '" + e.name + "' has no properties");
    if (e.row_size > 0 && e.count > (file_size - at) / e.row_size)
      fail(f.path, "truncated: element '" + e.name + "' declares " + std::to_string(e.count) + " rows of " +
                       std::to_string(e.row_size) + " bytes but only " + std::to_string(file_size - at) +
                       " bytes remain");
    e.data_offset = at;
    at += e.count * e.row_size;
  }
  if (at != file_size) fail(f.path, std::to_string(file_size - at) + " bytes after the last element (wrong counts?)");
  f.bytes = MappedFile(f.path, file_size);
}

// An ascii body: every value parsed into the elements' ascii_rows.
// Whether an ascii value is one that a binary field of `type` could hold: integral and in range
// for the integer types, within float's range (or +-inf, NaN) for f32. The loaders convert values
// to their declared types (a packed_* uint32, an 8-bit SH code), and converting one that does not
// fit is undefined behaviour; a binary file cannot hold such a value, so an ascii one may not.
bool fits_type(Type type, double v) {
  auto integer_in = [v](double lo, double hi) { return v >= lo && v <= hi && std::floor(v) == v; };
  switch (type) {
    case Type::i8:
      return integer_in(-128.0, 127.0);
    case Type::u8:
      return integer_in(0.0, 255.0);
    case Type::i16:
      return integer_in(-32768.0, 32767.0);
    case Type::u16:
      return integer_in(0.0, 65535.0);
    case Type::i32:
      return integer_in(-2147483648.0, 2147483647.0);
    case Type::u32:
      return integer_in(0.0, 4294967295.0);
    case Type::f32:
      return !std::isfinite(v) || std::fabs(v) <= static_cast<double>(std::numeric_limits<float>::max());
    case Type::f64:
      return true;
  }
  return false;
}

void read_ascii_body(std::istream& in, uint64_t body_offset, uint64_t body, File& f) {
  uint64_t values = 0;
  for (const auto& e : f.elements) {
    // Rows without values would make the row loop below run `count` times over nothing.
    if (e.properties.empty() && e.count > 0) fail(f.path, "element '" + e.name + "' has no properties");
    uint64_t element_values = 0;
    if (!checked_mul(e.count, e.properties.size(), &element_values) || !checked_add(values, element_values, &values))
      fail(f.path, "element '" + e.name + "' declares " + std::to_string(e.count) + " rows of " +
                       std::to_string(e.properties.size()) + " values: more than 2^64 values");
  }
  // Each ascii value takes at least two bytes (a digit and a separator).
  if (values > body / 2 + 1)
    fail(f.path, "truncated: header declares " + std::to_string(values) + " values but the body has " +
                     std::to_string(body) + " bytes");
  in.clear();
  in.seekg(static_cast<std::streamoff>(body_offset));
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const char* p = text.data();
  const char* end = p + text.size();
  for (auto& e : f.elements) {
    e.ascii_rows.resize(e.count * e.properties.size());
    for (uint64_t r = 0; r < e.count; ++r) {
      for (std::size_t k = 0; k < e.properties.size(); ++k) {
        while (p < end && (*p == ' ' || *p == '\t' || *p == '\n' || *p == '\r')) ++p;
        double v = 0;
        const auto res = std::from_chars(p, end, v);
        if (res.ec != std::errc())
          fail(f.path, "truncated or malformed ascii value at element '" + e.name + "' row " + std::to_string(r) +
                           " property '" + e.properties[k].name + "'");
        if (!fits_type(e.properties[k].type, v))
          fail(f.path, "ascii value " + std::string(p, res.ptr) + " at element '" + e.name + "' row " +
                           std::to_string(r) + " property '" + e.properties[k].name + "' does not fit its type");
        e.ascii_rows[r * e.properties.size() + k] = v;
        p = res.ptr;
      }
    }
  }
}

}  // namespace

File read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, "cannot open file");
  in.seekg(0, std::ios::end);
  const auto file_size = static_cast<uint64_t>(in.tellg());
  in.seekg(0);

  File f;
  f.path = path;
  const std::string header = read_header_text(in, path);
  const uint64_t body_offset = header.size();
  if (body_offset > file_size) fail(path, "header runs past the end of the file");
  parse_header(header, f);
  if (f.ascii)
    read_ascii_body(in, body_offset, file_size - body_offset, f);
  else
    read_binary_body(file_size, body_offset, f);
  return f;
}

}  // namespace catgs::ply
