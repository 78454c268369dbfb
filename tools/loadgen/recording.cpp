#include "loadgen/recording.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <sstream>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "proto/depth_grid_coding.h"

namespace catgs::loadgen {

namespace {

namespace pb = ::catgs::stream::v1;

std::ofstream open_out(const std::string& path, bool binary = false) {
  std::ofstream out(path, binary ? std::ios::binary : std::ios::out);
  if (!out) throw std::runtime_error(path + ": cannot write");
  out << std::setprecision(17);
  return out;
}

std::ifstream open_in(const std::string& path, bool binary = false) {
  std::ifstream in(path, binary ? std::ios::binary : std::ios::in);
  if (!in) throw std::runtime_error(path + ": cannot read (not a catgs-loadgen --record folder?)");
  return in;
}

// A line of a .tsv file: where it is ("FILE:LINE", for errors) and its fields.
struct TsvRow {
  std::string where;
  std::vector<std::string> fields;
  double number(std::size_t k) const;
  std::uint64_t count(std::size_t k, double max) const;
};

// The lines of a .tsv file that are not comments, each split into fields; `fields` per line or a
// runtime_error naming the file and line.
std::vector<TsvRow> read_tsv(const std::string& path, std::size_t fields) {
  std::ifstream in = open_in(path);
  std::vector<TsvRow> rows;
  int number = 0;
  for (std::string line; std::getline(in, line);) {
    ++number;
    if (line.empty() || line[0] == '#') continue;
    std::vector<std::string> row;
    std::stringstream ss(line);
    for (std::string f; std::getline(ss, f, '\t');) row.push_back(f);
    if (row.size() != fields)
      throw std::runtime_error(path + ":" + std::to_string(number) + ": " + std::to_string(row.size()) +
                               " fields, want " + std::to_string(fields));
    rows.push_back({path + ":" + std::to_string(number), std::move(row)});
  }
  return rows;
}

double number_of(const std::string& s, const std::string& where) {
  std::size_t used = 0;
  double v = 0;
  try {
    v = std::stod(s, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != s.size() || !std::isfinite(v)) throw std::runtime_error(where + ": '" + s + "' is not a number");
  return v;
}

double TsvRow::number(std::size_t k) const { return number_of(fields[k], where); }

// Field k as a whole number in [0, max] (2^53 at most: a double holds it exactly), checked
// before the cast: a float-to-integer cast out of range is undefined behaviour.
std::uint64_t TsvRow::count(std::size_t k, double max) const {
  const double v = number(k);
  if (!(v >= 0 && v <= std::min(max, 9007199254740992.0)) || v != std::floor(v))
    throw std::runtime_error(where + ": '" + fields[k] + "' is not a whole number in [0, " +
                             std::to_string(static_cast<std::uint64_t>(std::min(max, 9007199254740992.0))) + "]");
  return static_cast<std::uint64_t>(v);
}

// frames.tsv's depth_grid field: cols,rows,cell_px,inverse_depth_max,codes (hex), or "-".
std::string depth_grid_field(const std::optional<pb::DepthGrid>& g) {
  if (!g) return "-";
  std::ostringstream out;
  out << std::setprecision(9) << g->cols() << ',' << g->rows() << ',' << g->cell_px() << ',' << g->inverse_depth_max()
      << ',';
  static const char* kHex = "0123456789abcdef";
  for (const char c : g->inverse_depth()) {
    const auto b = static_cast<unsigned char>(c);
    out << kHex[b >> 4] << kHex[b & 15];
  }
  return out.str();
}

pb::DepthGrid depth_grid_of(const std::string& field, const std::string& where) {
  std::vector<std::string> parts;
  std::stringstream ss(field);
  for (std::string v; std::getline(ss, v, ',');) parts.push_back(v);
  if (parts.size() != 5)
    throw std::runtime_error(where + ": depth grid has " + std::to_string(parts.size()) +
                             " comma-separated parts, want 5");
  auto whole = [&](const std::string& v) {
    const double d = number_of(v, where);
    if (!(d >= 0 && d <= 4294967295.0) || d != std::floor(d))
      throw std::runtime_error(where + ": depth grid '" + v + "' is not a whole number");
    return static_cast<std::uint32_t>(d);
  };
  pb::DepthGrid g;
  g.set_cols(whole(parts[0]));
  g.set_rows(whole(parts[1]));
  g.set_cell_px(whole(parts[2]));
  g.set_inverse_depth_max(static_cast<float>(number_of(parts[3], where)));
  const std::string& hex = parts[4];
  if (hex.size() % 2 != 0) throw std::runtime_error(where + ": depth grid codes have an odd number of hex digits");
  std::string codes(hex.size() / 2, '\0');
  auto nibble = [&](char c) {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    throw std::runtime_error(where + ": depth grid code digit '" + std::string(1, c) + "' is not lower-case hex");
  };
  for (std::size_t i = 0; i < codes.size(); ++i)
    codes[i] = static_cast<char>((nibble(hex[2 * i]) << 4) | nibble(hex[2 * i + 1]));
  g.set_inverse_depth(std::move(codes));
  try {
    (void)server::unpack_depth_grid(g);  // its shape and codes agree
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(where + ": " + e.what());
  }
  return g;
}

}  // namespace

std::vector<double> visible_ms(const SessionRecording& r) {
  std::vector<double> out;
  out.reserve(r.frames.size());
  double link_free_ms = -1e300;  // when the link has sent the frame before
  for (const RecordedFrame& f : r.frames) {
    double leaves = f.arrived_ms;
    if (r.link.rate_mbit > 0) {
      // The access unit and the depth grid that travels with it.
      const std::size_t depth_bytes = f.depth_grid ? f.depth_grid->inverse_depth().size() : 0;
      leaves = std::max(leaves, link_free_ms) +
               8.0 * static_cast<double>(f.bytes + depth_bytes) / (1000.0 * r.link.rate_mbit);
      link_free_ms = leaves;
    }
    out.push_back(leaves + 0.5 * r.link.rtt_ms);
  }
  return out;
}

void write_recording(const SessionRecording& r, const std::string& dir) {
  std::filesystem::create_directories(dir);
  const nlohmann::json meta = {{"width", r.width},
                               {"height", r.height},
                               {"trace", r.trace_spec},
                               {"offset_s", r.offset_s},
                               {"seconds", r.seconds},
                               {"link_rtt_ms", r.link.rtt_ms},
                               {"link_rate_mbit", r.link.rate_mbit},
                               {"plane_distance", r.plane_distance},
                               {"scene_scale", r.scene_scale}};
  open_out(dir + "/meta.json") << meta.dump(1) << "\n";
  write_trace(r.trace, dir + "/display.trace");
  std::ofstream poses = open_out(dir + "/poses.tsv");
  poses << "# sequence\tsent_ms\ttrace_s\n";
  for (const RecordedPose& p : r.poses) poses << p.sequence << '\t' << p.sent_ms << '\t' << p.trace_s << '\n';
  std::ofstream frames = open_out(dir + "/frames.tsv");
  frames << "# "
            "sequence\tpose_sequence\tarrived_ms\tkey\twidth\theight\tlod_error_px\toffset\tbytes\tshown_pose\tdepth_"
            "grid\n";
  for (const RecordedFrame& f : r.frames) {
    frames << f.sequence << '\t' << f.pose_sequence << '\t' << f.arrived_ms << '\t' << (f.key ? 1 : 0) << '\t'
           << f.width << '\t' << f.height << '\t' << f.lod_error_px << '\t' << f.offset << '\t' << f.bytes << '\t';
    if (!f.shown_pose) frames << '-';
    for (std::size_t k = 0; f.shown_pose && k < f.shown_pose->size(); ++k)
      frames << (k ? "," : "") << (*f.shown_pose)[k];
    frames << '\t' << depth_grid_field(f.depth_grid) << '\n';
  }
  open_out(dir + "/stream.h264", true).write(r.stream.data(), static_cast<std::streamsize>(r.stream.size()));
}

SessionRecording read_recording(const std::string& dir) {
  SessionRecording r;
  const std::string meta_path = dir + "/meta.json";
  try {
    std::ifstream in = open_in(meta_path);
    const nlohmann::json meta = nlohmann::json::parse(in);
    r.width = meta.at("width").get<int>();
    r.height = meta.at("height").get<int>();
    r.trace_spec = meta.at("trace").get<std::string>();
    r.offset_s = meta.at("offset_s").get<double>();
    r.seconds = meta.at("seconds").get<double>();
    r.link.rtt_ms = meta.at("link_rtt_ms").get<double>();
    r.link.rate_mbit = meta.at("link_rate_mbit").get<double>();
    r.plane_distance = meta.at("plane_distance").get<double>();
    r.scene_scale = meta.at("scene_scale").get<double>();
  } catch (const nlohmann::json::exception& e) {
    throw std::runtime_error(meta_path + ": " + e.what());
  }
  r.trace = read_trace(dir + "/display.trace");
  if (r.trace.empty()) throw std::runtime_error(dir + "/display.trace: no camera");
  {
    std::ifstream in = open_in(dir + "/stream.h264", true);
    r.stream.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  for (const TsvRow& row : read_tsv(dir + "/poses.tsv", 3)) {
    RecordedPose p;
    p.sequence = static_cast<std::uint32_t>(row.count(0, 4294967295.0));
    p.sent_ms = row.number(1);
    p.trace_s = row.number(2);
    if (p.sequence != r.poses.size())
      throw std::runtime_error(row.where + ": pose " + row.fields[0] + " out of order (want " +
                               std::to_string(r.poses.size()) + ")");
    r.poses.push_back(p);
  }
  for (const TsvRow& row : read_tsv(dir + "/frames.tsv", 11)) {
    RecordedFrame f;
    f.sequence = static_cast<std::uint32_t>(row.count(0, 4294967295.0));
    f.pose_sequence = static_cast<std::uint32_t>(row.count(1, 4294967295.0));
    f.arrived_ms = row.number(2);
    f.key = row.fields[3] == "1";
    f.width = static_cast<int>(row.count(4, kMaxImageSide));
    f.height = static_cast<int>(row.count(5, kMaxImageSide));
    f.lod_error_px = static_cast<float>(row.number(6));
    f.offset = row.count(7, 1e18);
    f.bytes = row.count(8, 1e18);
    if (row.fields[9] != "-") {
      std::array<double, 8> pose{};
      std::stringstream ss(row.fields[9]);
      std::size_t k = 0;
      for (std::string v; std::getline(ss, v, ',');) {
        if (k == pose.size()) throw std::runtime_error(row.where + ": shown pose has more than 8 numbers");
        pose[k++] = number_of(v, row.where);
      }
      if (k != pose.size())
        throw std::runtime_error(row.where + ": shown pose has " + std::to_string(k) + " numbers, want 8");
      f.shown_pose = pose;
    }
    if (row.fields[10] != "-") f.depth_grid = depth_grid_of(row.fields[10], row.where);
    if (f.bytes > r.stream.size() || f.offset > r.stream.size() - f.bytes)  // no overflow
      throw std::runtime_error(row.where + ": frame ends past stream.h264 (" + std::to_string(r.stream.size()) +
                               " bytes)");
    if (f.pose_sequence >= r.poses.size())
      throw std::runtime_error(row.where + ": frame answers pose " + row.fields[1] + ", never sent");
    if (f.width < 1 || f.height < 1) throw std::runtime_error(row.where + ": frame size under 1 pixel");
    r.frames.push_back(f);
  }
  return r;
}

}  // namespace catgs::loadgen
