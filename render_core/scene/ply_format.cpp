// PLY header and body parsing with size checks done before any allocation a header could inflate.
#include "ply_format.h"

#include <charconv>
#include <cstring>
#include <fstream>
#include <sstream>

#include "scene/gaussian_model.h"

namespace catgs::ply {

namespace {
constexpr std::size_t kMaxHeaderBytes = 1 << 20;
}

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

File read_file(const std::string& path) {
  auto fail = [&](const std::string& problem) -> void { throw SceneFileError(path, problem); };
  std::ifstream in(path, std::ios::binary);
  if (!in) fail("cannot open file");
  in.seekg(0, std::ios::end);
  const auto file_size = static_cast<uint64_t>(in.tellg());
  in.seekg(0);

  File f;
  f.path = path;
  // Header: lines up to and including "end_header\n".
  std::string header;
  {
    std::string line;
    bool ended = false;
    while (header.size() < kMaxHeaderBytes && std::getline(in, line)) {
      header += line + "\n";
      if (!line.empty() && line.back() == '\r') line.pop_back();
      if (line == "end_header") {
        ended = true;
        break;
      }
    }
    if (header.rfind("ply", 0) != 0) fail("not a PLY file (no 'ply' magic line)");
    if (!ended) fail("PLY header has no end_header line");
  }
  const uint64_t body_offset = header.size();

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
        fail("unsupported PLY format '" + fmt + "' (binary_little_endian or ascii only)");
      have_format = true;
    } else if (word == "element") {
      Element e;
      std::string count;
      ls >> e.name >> count;
      uint64_t n = 0;
      const auto res = std::from_chars(count.data(), count.data() + count.size(), n);
      if (e.name.empty() || res.ec != std::errc() || res.ptr != count.data() + count.size())
        fail("malformed element count in " + where);
      e.count = n;
      f.elements.push_back(std::move(e));
    } else if (word == "property") {
      if (f.elements.empty()) fail("property before any element in " + where);
      std::string type, name;
      ls >> type >> name;
      if (type == "list") fail("list properties are not supported (" + where + ")");
      Property p;
      p.name = name;
      if (name.empty() || !parse_type(type, &p.type)) fail("bad property in " + where);
      Element& e = f.elements.back();
      if (e.find(name) >= 0) fail("duplicate property '" + name + "' in element " + e.name);
      p.offset = e.row_size;
      e.row_size += static_cast<std::size_t>(type_size(p.type));
      e.properties.push_back(p);
    } else {
      fail("unknown header keyword in " + where);
    }
  }
  if (!have_format) fail("PLY header has no format line");

  const uint64_t body = file_size - body_offset;
  if (!f.ascii) {
    // Check sizes against the file before allocating anything a header count could inflate.
    uint64_t at = body_offset;
    for (auto& e : f.elements) {
      if (e.row_size == 0 && e.count > 0) fail("element '" + e.name + "' has no properties");
      if (e.row_size > 0 && e.count > (file_size - at) / e.row_size)
        fail("truncated: element '" + e.name + "' declares " + std::to_string(e.count) + " rows of " +
             std::to_string(e.row_size) + " bytes but only " + std::to_string(file_size - at) + " bytes remain");
      e.data_offset = at;
      at += e.count * e.row_size;
    }
    if (at != file_size) fail(std::to_string(file_size - at) + " bytes after the last element (wrong counts?)");
    f.bytes.resize(file_size);
    in.seekg(0);
    if (!in.read(reinterpret_cast<char*>(f.bytes.data()), static_cast<std::streamsize>(file_size))) fail("read error");
  } else {
    uint64_t values = 0;
    for (const auto& e : f.elements) values += e.count * e.properties.size();
    // Each ascii value takes at least two bytes (a digit and a separator).
    if (values > body / 2 + 1)
      fail("truncated: header declares " + std::to_string(values) + " values but the body has " + std::to_string(body) +
           " bytes");
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
            fail("truncated or malformed ascii value at element '" + e.name + "' row " + std::to_string(r) +
                 " property '" + e.properties[k].name + "'");
          e.ascii_rows[r * e.properties.size() + k] = v;
          p = res.ptr;
        }
      }
    }
  }
  return f;
}

}  // namespace catgs::ply
