// /metrics: histogram buckets are cumulative with Prometheus `le` semantics, and every histogram
// family in the exposition text is consistent (non-decreasing buckets, +Inf bucket == _count).
#include <gtest/gtest.h>

#include <map>
#include <regex>
#include <sstream>
#include <vector>

#include "process/server_metrics.h"

namespace {

using catgs::server::Histogram;
using catgs::server::ServerMetrics;

TEST(Histogram, CumulativeBucketsWithInclusiveUpperBounds) {
  Histogram h({0.001, 0.01, 0.1});
  for (double v : {0.0005, 0.001, 0.002, 0.01, 0.05, 3.0}) h.observe(v);
  std::ostringstream o;
  h.write(o, "x_seconds", "kind=\"key\"");
  EXPECT_EQ(o.str(),
            "x_seconds_bucket{kind=\"key\",le=\"0.001\"} 2\n"
            "x_seconds_bucket{kind=\"key\",le=\"0.01\"} 4\n"
            "x_seconds_bucket{kind=\"key\",le=\"0.1\"} 5\n"
            "x_seconds_bucket{kind=\"key\",le=\"+Inf\"} 6\n"
            "x_seconds_sum{kind=\"key\"} 3.0635\n"
            "x_seconds_count{kind=\"key\"} 6\n");
  EXPECT_EQ(h.count(), 6u);
  EXPECT_THROW(Histogram({0.1, 0.1}), std::invalid_argument);
  EXPECT_THROW(Histogram({0.2, 0.1}), std::invalid_argument);
}

TEST(ServerMetrics, ExpositionHasConsistentStageHistograms) {
  ServerMetrics m;
  m.renderer = "cpu";
  m.encoder = "x264";
  m.pipeline = "catgs";
  for (int i = 0; i < 10; ++i) {
    m.queue_seconds.observe(0.001 * i);
    (i % 3 ? m.render_sub_seconds : m.render_key_seconds).observe(0.004 * i);
    m.convert_seconds.observe(0.0);
    m.encode_seconds.observe(0.007);
    m.speculation_window.observe(i % 5);
  }
  m.send_seconds.observe(2.5);  // above every bucket: only +Inf
  m.session_fps.observe(59.5);
  m.pose_to_frame_seconds.observe(0.04);
  m.pose_to_frame_seconds.observe(0.06);
  const std::string text = m.prometheus_text();
  EXPECT_NE(text.find("catgs_info{renderer=\"cpu\",encoder=\"x264\",pipeline=\"catgs\"} 1\n"), std::string::npos);
  EXPECT_NE(text.find("catgs_encoder_fallbacks_total 0\n"), std::string::npos);
  EXPECT_NE(text.find("catgs_dropped_frames_total 0\n"), std::string::npos);
  EXPECT_NE(text.find("catgs_render_frames_total{kind=\"sub\"} 0\n"), std::string::npos);

  // series (name + labels without le) -> buckets in order, and _count.
  std::map<std::string, std::vector<double>> buckets;
  std::map<std::string, double> inf, count;
  const std::regex bucket_re(R"re(^(\w+)_bucket\{(.*?),?le="([^"]+)"\} (\S+)$)re");
  const std::regex count_re(R"re(^(\w+)_count(?:\{(.*)\})? (\S+)$)re");
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    std::smatch s;
    if (std::regex_match(line, s, bucket_re)) {
      const std::string key = s[1].str() + "{" + s[2].str() + "}";
      if (s[3] == "+Inf")
        inf[key] = std::stod(s[4]);
      else
        buckets[key].push_back(std::stod(s[4]));
    } else if (std::regex_match(line, s, count_re)) {
      count[s[1].str() + "{" + s[2].str() + "}"] = std::stod(s[3]);
    }
  }
  const std::map<std::string, double> want = {{"catgs_queue_seconds{}", 10},
                                              {"catgs_render_seconds{kind=\"key\"}", 4},
                                              {"catgs_render_seconds{kind=\"sub\"}", 6},
                                              {"catgs_convert_seconds{}", 10},
                                              {"catgs_encode_seconds{}", 10},
                                              {"catgs_send_seconds{}", 1},
                                              {"catgs_speculation_window{}", 10},
                                              {"catgs_pose_to_frame_seconds{}", 2},
                                              {"catgs_session_fps{}", 1}};
  for (const auto& [key, n] : want) {
    SCOPED_TRACE(key);
    ASSERT_TRUE(count.count(key)) << text;
    EXPECT_EQ(count[key], n);
    EXPECT_EQ(inf[key], n);
    const auto& b = buckets[key];
    ASSERT_FALSE(b.empty());
    for (std::size_t i = 1; i < b.size(); ++i) EXPECT_LE(b[i - 1], b[i]);
    EXPECT_LE(b.back(), n);
  }
  EXPECT_EQ(buckets["catgs_send_seconds{}"].back(), 0);  // 2.5 s is above the largest bound
  EXPECT_NE(text.find("catgs_pose_to_frame_seconds_sum 0.1\n"), std::string::npos) << text;
  EXPECT_NE(text.find("catgs_session_fps_bucket{le=\"45\"} 0\ncatgs_session_fps_bucket{le=\"60\"} 1\n"),
            std::string::npos)
      << text;
  EXPECT_EQ(buckets["catgs_encode_seconds{}"].front(), 0);  // 7 ms is above 0.5 ms
  EXPECT_EQ(text.find("# TYPE catgs_render_seconds histogram"), text.rfind("# TYPE catgs_render_seconds histogram"))
      << "one TYPE line per family";
}

// The auto splat budget's throughput (render/lod_bound.h): a frame's Gaussians over its render
// time, times the frames rendering on the GPU with it (four lanes sharing the GPU each take about
// four times as long); the best seen is kept; other devices and small frames are not counted.
TEST(ServerMetrics, GpuThroughputCountsTheFramesRenderingTogether) {
  ServerMetrics m;
  m.set_gpus({0, 3}, [] { return std::vector<std::int64_t>{0, 0}; });
  EXPECT_EQ(m.gpu_splats_per_ms(3), 0.0);
  EXPECT_EQ(m.gpu_render_begin(3), 1);
  EXPECT_EQ(m.gpu_render_begin(3), 2);
  EXPECT_EQ(m.gpu_render_begin(0), 1);  // another GPU's count
  EXPECT_EQ(m.gpu_render_end(3), 2);
  EXPECT_EQ(m.gpu_render_end(3), 1);
  m.observe_gpu_throughput(3, 2000000, 2.0);  // alone: 1 M a ms
  EXPECT_EQ(m.gpu_splats_per_ms(3), 1000000.0);
  m.observe_gpu_throughput(3, 2000000, 4.0, 3.0);  // three together, each slower: 1.5 M a ms
  EXPECT_EQ(m.gpu_splats_per_ms(3), 1500000.0);
  m.observe_gpu_throughput(3, 2000000, 8.0, 2.0);  // slower: the best stays
  m.observe_gpu_throughput(3, 99999, 0.01);        // too few Gaussians to say
  m.observe_gpu_throughput(7, 2000000, 0.5);       // not a GPU of set_gpus
  EXPECT_EQ(m.gpu_splats_per_ms(3), 1500000.0);
  EXPECT_EQ(m.gpu_splats_per_ms(0), 0.0);
}

// A GPU whose sessions drew at --lod-max-error over their splat budget (render/lod_bound.h) is
// short for a while after the last such frame, and only that GPU; the bound of each frame is a
// histogram.
TEST(ServerMetrics, GpuBudgetShortForAWhileAfterTheLastFrameOverIt) {
  ServerMetrics m;
  std::vector<std::int64_t> sessions{0, 10};
  m.set_gpus({0, 3}, [&sessions] { return sessions; });
  EXPECT_FALSE(m.gpu_budget_short(3, 0, 2000)) << "never short";
  m.note_gpu_budget_short(3, 10000);  // with 10 sessions on GPU 3
  EXPECT_TRUE(m.gpu_budget_short(3, 10000, 2000));
  sessions[1] = 11;  // a visitor at the door counts as placed there
  EXPECT_TRUE(m.gpu_budget_short(3, 12000, 2000));
  EXPECT_FALSE(m.gpu_budget_short(3, 12001, 2000)) << "no frame over it for longer than the window";
  sessions[1] = 9;  // a visitor left since: room for one
  EXPECT_FALSE(m.gpu_budget_short(3, 11000, 2000));
  sessions[1] = 10;
  EXPECT_FALSE(m.gpu_budget_short(0, 10000, 2000)) << "another GPU";
  m.note_gpu_budget_short(7, 10000);  // not a GPU of set_gpus: ignored
  EXPECT_FALSE(m.gpu_budget_short(7, 10000, 2000));
  m.frame_lod_bound_px.observe(2.0);
  m.frame_lod_bound_px.observe(2.83);
  m.lod_over_budget_frames_total++;
  const std::string text = m.prometheus_text();
  EXPECT_NE(text.find("catgs_frame_lod_bound_px_bucket{le=\"2.01\"} 1"), std::string::npos) << text;
  EXPECT_NE(text.find("catgs_frame_lod_bound_px_bucket{le=\"2.83\"} 2"), std::string::npos);
  EXPECT_NE(text.find("catgs_lod_over_budget_frames_total 1"), std::string::npos);
  EXPECT_NE(text.find("catgs_splat_budget_refusals_total 0"), std::string::npos);
}

}  // namespace
