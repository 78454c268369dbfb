#include "encode_bench/rd_settings.h"

#include <sstream>
#include <stdexcept>

namespace catgs::encode_bench {

namespace {

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::stringstream in(s);
  for (std::string item; std::getline(in, item, sep);)
    if (!item.empty()) out.push_back(item);
  return out;
}

int to_int(const std::string& row, const std::string& key, const std::string& v, int lo, int hi) {
  std::size_t used = 0;
  int x = 0;
  try {
    x = std::stoi(v, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != v.size() || v.empty() || x < lo || x > hi)
    throw std::invalid_argument("setting '" + row + "': " + key + " must be an integer in [" + std::to_string(lo) +
                                ", " + std::to_string(hi) + "], got '" + v + "'");
  return x;
}

}  // namespace

std::vector<RdSetting> parse_rd_settings(const std::string& spec, int usable_cores) {
  std::vector<RdSetting> rows;
  for (const std::string& row : split(spec, ';')) {
    RdSetting s;
    s.label = row;
    s.policy.usable_cores = usable_cores;
    for (const std::string& kv : split(row, ',')) {
      const auto eq = kv.find('=');
      if (eq == std::string::npos) throw std::invalid_argument("setting '" + row + "': '" + kv + "' is not key=value");
      const std::string k = kv.substr(0, eq), v = kv.substr(eq + 1);
      if (k == "crf")
        s.policy.crf = to_int(row, k, v, 0, 51);
      else if (k == "bitrate")
        s.policy.bitrate_kbps = v == "auto" ? -1 : v == "off" ? 0 : to_int(row, k, v, 100, 1000000);
      else if (k == "bpp" && v == "auto")
        s.policy.content_rate = true;
      else if (k == "bpp") {
        try {
          s.policy.bits_per_pixel = std::stod(v);
        } catch (const std::exception&) {
          s.policy.bits_per_pixel = -1;
        }
        if (!(s.policy.bits_per_pixel > 0 && s.policy.bits_per_pixel < 10))
          throw std::invalid_argument("setting '" + row + "': bpp must be auto or in (0, 10), got '" + v + "'");
      } else if (k == "vbv")
        s.policy.vbv_buffer_ms = to_int(row, k, v, 1, 10000);
      else if (k == "ir")
        s.policy.intra_refresh_frames = to_int(row, k, v, 0, 1000);
      else if (k == "threads")
        s.policy.threads = to_int(row, k, v, 0, 64);
      else if (k == "speed")
        s.policy.av1_speed = to_int(row, k, v, 5, 10);
      else if (k == "encoder") {
        if (v != "x264" && v != "av1")
          throw std::invalid_argument("setting '" + row + "': encoder must be x264 or av1, got '" + v + "'");
        s.encoder = v;
      } else if (k == "sessions")
        s.sessions = to_int(row, k, v, 1, 256);
      else if (k == "preset") {
        if (v != "auto" && !server::is_x264_preset(v))
          throw std::invalid_argument("setting '" + row + "': preset must be auto or an x264 preset, got '" + v + "'");
        s.policy.x264_preset = v;
      } else
        throw std::invalid_argument("setting '" + row + "': unknown key '" + k +
                                    "' (crf, bitrate, bpp, vbv, ir, threads, preset, sessions, encoder, speed)");
    }
    rows.push_back(s);
  }
  if (rows.empty()) throw std::invalid_argument("--settings names no setting");
  return rows;
}

}  // namespace catgs::encode_bench
