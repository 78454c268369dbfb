// Annotations beside a scene (annotations.h): validation with nlohmann-json, atomic writes.
#include "session/annotations.h"

#include <atomic>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <stdexcept>
#include <system_error>

#include <unistd.h>

#include <nlohmann/json.hpp>

namespace catgs::server {

namespace {

using json = nlohmann::json;
constexpr double kMaxComponent = 1e30;  // as Pose (message_validation.h)

// Thrown with the JSON path of the bad value; normalise_annotations prefixes the source.
struct Bad : std::invalid_argument {
  Bad(const std::string& where, const std::string& what) : std::invalid_argument(where + ": " + what) {}
};

const json& member(const json& object, const char* key, const std::string& where) {
  const auto it = object.find(key);
  if (it == object.end()) throw Bad(where, std::string("missing \"") + key + "\"");
  return *it;
}

double number(const json& v, const std::string& where) {
  if (!v.is_number()) throw Bad(where, "expected a number");
  const double x = v.get<double>();
  if (!std::isfinite(x) || std::fabs(x) > kMaxComponent) throw Bad(where, "not a finite number within +-1e30");
  return x;
}

std::string text(const json& v, const std::string& where, std::size_t min_bytes, std::size_t max_bytes) {
  if (!v.is_string()) throw Bad(where, "expected a string");
  const std::string s = v.get<std::string>();
  if (s.size() < min_bytes || s.size() > max_bytes)
    throw Bad(where, "expected " + std::to_string(min_bytes) + ".." + std::to_string(max_bytes) + " bytes, got " +
                         std::to_string(s.size()));
  return s;
}

json numbers(const json& v, std::size_t n, const std::string& where) {
  if (!v.is_array() || v.size() != n) throw Bad(where, "expected " + std::to_string(n) + " numbers");
  json out = json::array();
  for (std::size_t i = 0; i < n; ++i) out.push_back(number(v[i], where + "[" + std::to_string(i) + "]"));
  return out;
}

json view(const json& v, const std::string& where) {
  if (!v.is_object()) throw Bad(where, "expected an object");
  json out;
  out["position"] = numbers(member(v, "position", where), 3, where + ".position");
  out["orientation"] = numbers(member(v, "orientation", where), 4, where + ".orientation");
  double norm = 0;
  for (const json& c : out["orientation"]) norm += c.get<double>() * c.get<double>();
  if (!(norm > 1e-12)) throw Bad(where + ".orientation", "a zero quaternion");
  const double fov = number(member(v, "fov", where), where + ".fov");
  if (!(fov > 1.0 && fov < 170.0)) throw Bad(where + ".fov", "expected degrees in (1, 170)");
  out["fov"] = fov;
  return out;
}

json hotspot(const json& h, const std::string& where) {
  if (!h.is_object()) throw Bad(where, "expected an object");
  json out;
  out["id"] = text(member(h, "id", where), where + ".id", 1, kMaxHotspotIdBytes);
  out["title"] = text(member(h, "title", where), where + ".title", 1, kMaxHotspotTitleBytes);
  out["text"] = h.contains("text") ? text(h["text"], where + ".text", 0, kMaxHotspotTextBytes) : std::string();
  out["position"] = numbers(member(h, "position", where), 3, where + ".position");
  if (h.contains("view") && !h["view"].is_null()) out["view"] = view(h["view"], where + ".view");
  return out;
}

json annotations(const json& doc) {
  if (!doc.is_object()) throw Bad("top level", "expected an object {\"version\": 1, \"hotspots\": [...]}");
  const json& version = member(doc, "version", "top level");
  if (!version.is_number_integer() || version.get<long long>() != 1) throw Bad("version", "expected 1");
  json out;
  out["version"] = 1;
  if (doc.contains("metres_per_unit") && !doc["metres_per_unit"].is_null()) {
    const double m = number(doc["metres_per_unit"], "metres_per_unit");
    if (!(m > 0)) throw Bad("metres_per_unit", "expected a positive number");
    out["metres_per_unit"] = m;
  }
  const json& list = member(doc, "hotspots", "top level");
  if (!list.is_array()) throw Bad("hotspots", "expected an array");
  if (list.size() > kMaxHotspots)
    throw Bad("hotspots", std::to_string(list.size()) + " hotspots, at most " + std::to_string(kMaxHotspots));
  out["hotspots"] = json::array();
  std::set<std::string> ids;
  for (std::size_t i = 0; i < list.size(); ++i) {
    const std::string where = "hotspots[" + std::to_string(i) + "]";
    json h = hotspot(list[i], where);
    if (!ids.insert(h["id"].get<std::string>()).second) throw Bad(where + ".id", "a second hotspot with this id");
    out["hotspots"].push_back(std::move(h));
  }
  if (doc.contains("tour") && !doc["tour"].is_null()) {
    const json& tour = doc["tour"];
    if (!tour.is_array() || tour.size() > kMaxHotspots) throw Bad("tour", "expected an array of hotspot ids");
    out["tour"] = json::array();
    for (std::size_t i = 0; i < tour.size(); ++i) {
      const std::string where = "tour[" + std::to_string(i) + "]";
      const std::string id = text(tour[i], where, 1, kMaxHotspotIdBytes);
      if (!ids.count(id)) throw Bad(where, "no hotspot has the id '" + id + "'");
      out["tour"].push_back(id);
    }
  }
  return out;
}

}  // namespace

std::string annotations_path(const std::string& scene_path) {
  return std::filesystem::path(scene_path).replace_extension(".hotspots.json").string();
}

std::string normalise_annotations(std::string_view text, const std::string& source) {
  if (text.size() > kMaxAnnotationsBytes)
    throw std::invalid_argument(source + ": " + std::to_string(text.size()) + " bytes, at most " +
                                std::to_string(kMaxAnnotationsBytes));
  json doc;
  try {
    doc = json::parse(text);
  } catch (const json::parse_error& e) {
    // e.byte: where the parser gave up, 1-based.
    throw std::invalid_argument(source + ": not JSON (at byte " + std::to_string(e.byte) + ")");
  }
  try {
    return annotations(doc).dump();
  } catch (const Bad& e) {
    throw std::invalid_argument(source + ": " + e.what());
  }
}

AnnotationsFile read_annotations(const std::string& scene_path) {
  const std::string path = annotations_path(scene_path);
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) return {};
  AnnotationsFile out;
  const auto size = std::filesystem::file_size(path, ec);
  if (ec) return {"", path + ": cannot read it (" + ec.message() + ")"};
  // Checked before reading: a huge file is refused without being read into memory.
  if (size > kMaxAnnotationsBytes)
    return {"", path + ": " + std::to_string(size) + " bytes, at most " + std::to_string(kMaxAnnotationsBytes)};
  std::ifstream in(path, std::ios::binary);
  std::stringstream buffer;
  buffer << in.rdbuf();
  if (!in) return {"", path + ": cannot read it"};
  try {
    out.json = normalise_annotations(buffer.str(), path);
  } catch (const std::invalid_argument& e) {
    out.error = e.what();
  }
  return out;
}

std::string write_annotations(const std::string& scene_path, std::string_view text) {
  const std::string path = annotations_path(scene_path);
  const std::string normal = normalise_annotations(text, path);
  // A temporary name of this process and call, so two sessions saving at once never share one.
  static std::atomic<unsigned> counter{0};
  const std::string tmp = path + ".tmp" + std::to_string(::getpid()) + "." + std::to_string(counter++);
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    out << normal << '\n';
    out.close();
    if (!out) {
      std::error_code ignored;
      std::filesystem::remove(tmp, ignored);
      throw std::runtime_error(path + ": cannot write it (" + tmp + ")");
    }
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
    throw std::runtime_error(path + ": cannot replace it (" + ec.message() + ")");
  }
  return normal;
}

}  // namespace catgs::server
