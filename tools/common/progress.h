// A progress report for long tool runs (catgs-render --video): on a terminal, one line redrawn in
// place ("\r") with a bar, the count, the rate and the time left; elsewhere (a log, a pipe, CI) a
// plain line every 5% and at the end, so logs stay readable.
//
// Time left (ETA) = the items still to do at the mean rate so far (items / elapsed seconds).
#pragma once

#include <chrono>
#include <cstdio>
#include <string>

namespace catgs::tools {

class Progress {
 public:
  // `total` items (> 0) named `unit` ("frames"), written to `out`; `tty`: draw the redrawn bar
  // (pass isatty(fileno(out))).
  Progress(std::FILE* out, bool tty, long total, std::string unit);
  // `done` items are finished (0..total). Redraws at most 10 times a second on a terminal; the
  // last call (done == total) always prints and ends the line.
  void update(long done);

  // The text of one report, e.g. "[=====>    ] 45% 135/300 frames, 3.2 frames/s, 0:51 left"
  // (the bar only when `bar`). Public for tests.
  static std::string line(long done, long total, const std::string& unit, double elapsed_s, bool bar);
  // "M:SS" or "H:MM:SS" for a duration in seconds (negative or not finite: "?").
  static std::string clock(double seconds);

 private:
  std::FILE* out_;
  bool tty_;
  long total_;
  std::string unit_;
  std::chrono::steady_clock::time_point start_, last_draw_;
  int last_percent_ = -1;  // the last plain line's percentage, in steps of 5
};

}  // namespace catgs::tools
