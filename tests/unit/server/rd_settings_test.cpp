// catgs-encode-bench's settings rows (tools/encode_bench/rd_settings.h).
#include <gtest/gtest.h>

#include <stdexcept>

#include "encode_bench/rd_settings.h"

namespace {

using catgs::encode_bench::parse_rd_settings;

TEST(RdSettings, RowsKeepTheServerDefaultsForKeysLeftOut) {
  const auto rows = parse_rd_settings("crf=28,bitrate=off,threads=4;bitrate=6000,vbv=100,ir=30,sessions=10", 16);
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(rows[0].label, "crf=28,bitrate=off,threads=4");
  EXPECT_EQ(rows[0].policy.crf, 28);
  EXPECT_EQ(rows[0].policy.bitrate_kbps, 0);
  EXPECT_EQ(rows[0].policy.threads, 4);
  EXPECT_EQ(rows[0].sessions, 1);
  EXPECT_EQ(rows[1].policy.crf, catgs::server::EncoderPolicy{}.crf);
  EXPECT_EQ(rows[1].policy.bitrate_kbps, 6000);
  EXPECT_EQ(rows[1].policy.vbv_buffer_ms, 100);
  EXPECT_EQ(rows[1].policy.intra_refresh_frames, 30);
  EXPECT_EQ(rows[1].sessions, 10);
  EXPECT_EQ(rows[1].policy.usable_cores, 16);
  EXPECT_EQ(parse_rd_settings("bitrate=auto,bpp=0.05", 2)[0].policy.bits_per_pixel, 0.05);
  EXPECT_FALSE(parse_rd_settings("bitrate=auto,bpp=0.05", 2)[0].policy.content_rate);
  EXPECT_TRUE(parse_rd_settings("bpp=auto", 2)[0].policy.content_rate);  // the content-aware rate
}

TEST(RdSettings, BadRowsNameTheRowAndTheKey) {
  EXPECT_THROW(parse_rd_settings("", 4), std::invalid_argument);
  EXPECT_THROW(parse_rd_settings("crf=60", 4), std::invalid_argument);
  EXPECT_THROW(parse_rd_settings("crf=2x", 4), std::invalid_argument);
  EXPECT_THROW(parse_rd_settings("speed=3", 4), std::invalid_argument);
  EXPECT_THROW(parse_rd_settings("threads", 4), std::invalid_argument);
  EXPECT_THROW(parse_rd_settings("bpp=-1", 4), std::invalid_argument);
  try {
    parse_rd_settings("crf=20;sessions=0", 4);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("sessions=0"), std::string::npos) << e.what();
  }
}

}  // namespace
