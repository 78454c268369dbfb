#include "common/progress.h"

#include <algorithm>
#include <cmath>

namespace catgs::tools {

namespace {

constexpr int kBarWidth = 30;
constexpr double kRedrawSeconds = 0.1;
constexpr int kPlainStepPercent = 5;

}  // namespace

Progress::Progress(std::FILE* out, bool tty, long total, std::string unit)
    : out_(out), tty_(tty), total_(std::max(total, 1L)), unit_(std::move(unit)) {
  start_ = last_draw_ = std::chrono::steady_clock::now();
}

std::string Progress::clock(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0.0) return "?";
  const long s = std::lround(seconds);
  char buf[32];
  if (s >= 3600)
    std::snprintf(buf, sizeof buf, "%ld:%02ld:%02ld", s / 3600, s / 60 % 60, s % 60);
  else
    std::snprintf(buf, sizeof buf, "%ld:%02ld", s / 60, s % 60);
  return buf;
}

std::string Progress::line(long done, long total, const std::string& unit, double elapsed_s, bool bar) {
  const double share = total > 0 ? static_cast<double>(std::clamp(done, 0L, total)) / static_cast<double>(total) : 1.0;
  std::string text;
  if (bar) {
    const int filled = static_cast<int>(share * kBarWidth);
    text = "[" + std::string(static_cast<std::size_t>(filled), '=') + (filled < kBarWidth ? ">" : "") +
           std::string(static_cast<std::size_t>(std::max(kBarWidth - filled - 1, 0)), ' ') + "] ";
  }
  const double rate = elapsed_s > 0.0 ? static_cast<double>(done) / elapsed_s : 0.0;
  const double left = rate > 0.0 ? static_cast<double>(total - done) / rate : -1.0;
  char buf[160];
  std::snprintf(buf, sizeof buf, "%3d%% %ld/%ld %s, %.2f %s/s, %s left", static_cast<int>(share * 100.0), done, total,
                unit.c_str(), rate, unit.c_str(), clock(left).c_str());
  return text + buf;
}

void Progress::update(long done) {
  const auto now = std::chrono::steady_clock::now();
  const double elapsed = std::chrono::duration<double>(now - start_).count();
  const bool last = done >= total_;
  if (tty_) {
    if (!last && std::chrono::duration<double>(now - last_draw_).count() < kRedrawSeconds) return;
    last_draw_ = now;
    // \033[K clears what a longer earlier line left behind.
    std::fprintf(out_, "\r%s\033[K%s", line(done, total_, unit_, elapsed, true).c_str(), last ? "\n" : "");
  } else {
    const int percent = static_cast<int>(100 * std::min(done, total_) / total_) / kPlainStepPercent * kPlainStepPercent;
    if (percent == last_percent_ && !last) return;
    if (last && last_percent_ == 100) return;
    last_percent_ = percent;
    std::fprintf(out_, "%s\n", line(done, total_, unit_, elapsed, false).c_str());
  }
  std::fflush(out_);
}

}  // namespace catgs::tools
