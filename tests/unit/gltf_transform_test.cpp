// glTF node transforms and quantized attributes (issue 18), against splat-transform: its actions
// (-s scale, -r Euler degrees, -t translate, applied in order) work in its own axes, which are the
// glTF file's (its .glb writer writes them as they are: `splat-transform IN -t 1,2,3 OUT.ply` moves
// a PLY's centres by (-1, -2, 3), the 180-degree turn about z of gltf_file.h). So a node transform
// T * R * S put into splat-transform's .glb must render as splat-transform's own `-s -r -t` of the
// source does: centres, rotations, scales and, on flowers_sh3, the SH bands 1-3 turned with the
// node. The quantized file's reference is splat-transform's float .glb it was made from, read back
// by the same reader, so only the dequantization rules (glTF 2.0, "normalized") are under test there.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <iostream>
#include <string>

#include <nlohmann/json.hpp>

#include "scene/ply_io.h"
#include "scene_files.h"
#include "splat_transform.h"
#include "test_data.h"

namespace {

using namespace catgs;
using nlohmann::json;

constexpr double kSameDb = 50.0;

// A .glb split into its JSON and binary chunks, and put back together (glTF 2.0 section 4.4:
// a 12-byte header, then chunks of length, type and data, each padded to 4 bytes).
struct Glb {
  json gltf;
  std::string bin;
};

uint32_t u32(const std::string& b, std::size_t at) {
  uint32_t v = 0;
  std::memcpy(&v, b.data() + at, 4);
  return v;
}

Glb read_glb(const std::string& path) {
  const std::string b = test::read_bytes(path);
  Glb g;
  EXPECT_GE(b.size(), 20u);
  const uint32_t json_len = u32(b, 12);
  g.gltf = json::parse(b.substr(20, json_len));
  const std::size_t bin_at = 20 + json_len;
  if (bin_at + 8 <= b.size()) g.bin = b.substr(bin_at + 8, u32(b, bin_at));
  return g;
}

void write_glb(const std::string& path, const Glb& g) {
  std::string text = g.gltf.dump();
  text.append((4 - text.size() % 4) % 4, ' ');
  std::string bin = g.bin;
  bin.append((4 - bin.size() % 4) % 4, '\0');
  auto put = [](std::string& out, uint32_t v) { out.append(reinterpret_cast<const char*>(&v), 4); };
  std::string out = "glTF";
  put(out, 2);
  put(out, static_cast<uint32_t>(12 + 8 + text.size() + 8 + bin.size()));
  put(out, static_cast<uint32_t>(text.size()));
  out += "JSON" + text;
  put(out, static_cast<uint32_t>(bin.size()));
  out += std::string("BIN\0", 4) + bin;
  test::write_bytes(path, out);
}

// The test's transform, in glTF axes: T(0.3, -0.2, 0.5) * R_y(30 degrees) * S(1.5).
constexpr double kDeg = 30.0, kScale = 1.5;
const double kT[3] = {0.3, -0.2, 0.5};
const char* const kActions = "-s 1.5 -r 0,30,0 -t 0.3,-0.2,0.5";

json y_rotation() {  // (x, y, z, w)
  const double h = kDeg * M_PI / 360.0;
  return json::array({0.0, std::sin(h), 0.0, std::cos(h)});
}

// Our read of `glb` against splat-transform's -s -r -t of `source`, rendered at views around the
// transformed scene (min PSNR over them).
double psnr_against_transformed(const std::string& glb, const std::string& source, const std::string& dir) {
  const std::string ref = dir + "/reference.ply";
  const std::string err = test::splat_transform(source, ref, "", kActions);
  EXPECT_TRUE(err.empty()) << err;
  if (!err.empty()) return 0.0;
  const GaussianModel ours = load_scene(glb), reference = load_scene(ref);
  EXPECT_EQ(ours.size(), reference.size());
  if (ours.size() != reference.size()) return 0.0;
  return test::min_render_psnr(ours, reference, test::comparison_views(reference));
}

// The transform as TRS on a parent and a child node (translation on a new root, rotation and
// scale on splat-transform's node), and as one column-major matrix: both must match.
TEST(GltfTransforms, NodeTransformsMatchSplatTransformsActions) {
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  CATGS_REQUIRE_DATA(flowers, "scenes/flowers_sh3.ply");
  const std::string dir = test::temp_dir(), plain = dir + "/plain.glb";
  ASSERT_EQ(test::splat_transform(flowers, plain), "");
  const Glb g = read_glb(plain);
  ASSERT_EQ(g.gltf["scenes"][0]["nodes"], json::array({0}));

  Glb trs = g;
  trs.gltf["nodes"][0]["rotation"] = y_rotation();
  trs.gltf["nodes"][0]["scale"] = {kScale, kScale, kScale};
  trs.gltf["nodes"].push_back({{"children", {0}}, {"translation", {kT[0], kT[1], kT[2]}}});
  trs.gltf["scenes"][0]["nodes"] = {1};
  write_glb(dir + "/trs.glb", trs);
  const double psnr_trs = psnr_against_transformed(dir + "/trs.glb", flowers, dir);
  std::cout << "[ info ] flowers_sh3 .glb, T on a parent node, R S on its child: ours vs splat-transform " << kActions
            << ": " << psnr_trs << " dB\n";
  EXPECT_GE(psnr_trs, kSameDb);

  // T * R * S as a matrix: columns R * s, then T.
  const double a = kDeg * M_PI / 180.0, c = std::cos(a) * kScale, s = std::sin(a) * kScale;
  Glb mat = g;
  mat.gltf["nodes"][0]["matrix"] = {c, 0, -s, 0, 0, kScale, 0, 0, s, 0, c, 0, kT[0], kT[1], kT[2], 1};
  write_glb(dir + "/matrix.glb", mat);
  const GaussianModel a_trs = load_scene(dir + "/trs.glb"), a_mat = load_scene(dir + "/matrix.glb");
  ASSERT_EQ(a_trs.size(), a_mat.size());
  double worst = 0;
  for (std::size_t i = 0; i < a_trs.means.size(); ++i)
    worst = std::max(worst, static_cast<double>(std::fabs(a_trs.means[i] - a_mat.means[i])));
  EXPECT_LT(worst, 1e-5) << "the matrix and the TRS nodes place the Gaussians apart";

  // Untransformed, the same file renders as its source (what the reader did before nodes).
  const GaussianModel untransformed = load_scene(plain), source = load_scene(flowers);
  EXPECT_GE(test::min_render_psnr(untransformed, source, test::comparison_views(source)), kSameDb);
}

// Two nodes drawing the same mesh: both copies, each with its transform.
TEST(GltfTransforms, TwoNodesOfOneMeshGiveTwoCopies) {
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  const std::string dir = test::temp_dir(), plain = dir + "/biker.glb";
  ASSERT_EQ(test::splat_transform(test::bundled_scene(), plain), "");
  Glb g = read_glb(plain);
  g.gltf["nodes"].push_back({{"mesh", 0}, {"translation", {10.0, 0.0, 0.0}}});
  g.gltf["scenes"][0]["nodes"] = {0, 1};
  write_glb(dir + "/two.glb", g);
  const GaussianModel one = load_scene(plain), two = load_scene(dir + "/two.glb");
  ASSERT_EQ(two.size(), 2 * one.size());
  const std::size_t n = one.size();
  for (std::size_t i = 0; i < n; i += 997) {
    EXPECT_EQ(two.means[3 * i], one.means[3 * i]);
    // glTF +x is our -x (gltf_file.h): the second copy sits 10 units along our -x.
    EXPECT_NEAR(two.means[3 * (n + i)], one.means[3 * i] - 10.0f, 1e-4);
    EXPECT_EQ(two.means[3 * (n + i) + 1], one.means[3 * i + 1]);
  }
}

// Shear and non-uniform scale cannot be carried by a Gaussian's rotation and scales plus rotated
// SH: refused with the node named, as are a cycle, a node that does not exist and a component
// type outside glTF's and KHR_mesh_quantization's.
TEST(GltfTransforms, UnsupportedTransformsAndBrokenTreesAreNamed) {
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  const std::string dir = test::temp_dir(), plain = dir + "/biker.glb";
  ASSERT_EQ(test::splat_transform(test::bundled_scene(), plain), "");
  const Glb g = read_glb(plain);
  Glb stretched = g;
  stretched.gltf["nodes"][0]["scale"] = {1.0, 2.0, 1.0};
  write_glb(dir + "/stretched.glb", stretched);
  test::expect_scene_error(dir + "/stretched.glb", "node 0: only rotation, uniform scale and translation");
  Glb mirrored = g;
  mirrored.gltf["nodes"][0]["scale"] = {-1.0, -1.0, -1.0};
  write_glb(dir + "/mirrored.glb", mirrored);
  test::expect_scene_error(dir + "/mirrored.glb", "node 0: only rotation");
  Glb cycle = g;
  cycle.gltf["nodes"][0]["children"] = {0};
  write_glb(dir + "/cycle.glb", cycle);
  test::expect_scene_error(dir + "/cycle.glb", "node 0 is its own ancestor");
  Glb wide = g;  // 32-bit integers are no KHR_mesh_quantization type
  wide.gltf["accessors"][wide.gltf["meshes"][0]["primitives"][0]["attributes"]["POSITION"].get<int>()]
           ["componentType"] = 5125;
  write_glb(dir + "/wide.glb", wide);
  test::expect_scene_error(dir + "/wide.glb", "POSITION has component type 5125, expected float (5126) or an 8-");
  Glb dangling = g;
  dangling.gltf["scenes"][0]["nodes"] = {7};
  write_glb(dir + "/dangling.glb", dangling);
  test::expect_scene_error(dir + "/dangling.glb", "names node 7, which does not exist");
}

// KHR_mesh_quantization: POSITION as normalized int16 with the node scaling and offsetting it back
// (the extension's usual layout), ROTATION as normalized int16 and OPACITY as normalized uint8.
// SCALE stays float, divided by the node's scale. Reference: the float .glb they came from.
// Quantizing the centres to 1/32767 of the scene's half-extent changes the picture a little (the
// bundled biker's opacities are 8-bit already); the bound says how little.
TEST(GltfTransforms, QuantizedAttributesDequantizeAsGltfSays) {
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  const std::string dir = test::temp_dir(), plain = dir + "/biker.glb";
  ASSERT_EQ(test::splat_transform(test::bundled_scene(), plain), "");
  Glb g = read_glb(plain);
  json& attrs = g.gltf["meshes"][0]["primitives"][0]["attributes"];
  const std::string ext = "KHR_gaussian_splatting:";
  auto floats_of = [&](int accessor, int comps) {
    const json& a = g.gltf["accessors"][accessor];
    const json& v = g.gltf["bufferViews"][a["bufferView"].get<int>()];
    const std::size_t at = v["byteOffset"].get<std::size_t>() + a.value("byteOffset", std::size_t{0});
    std::vector<float> out(a["count"].get<std::size_t>() * comps);
    std::memcpy(out.data(), g.bin.data() + at, out.size() * sizeof(float));
    return out;
  };
  // Appends a normalized integer accessor of `comps` components and replaces attribute `name`.
  auto quantize = [&](const std::string& name, int comps, bool is_signed, int bytes, auto to_unit) {
    const int old = attrs[name].get<int>();
    const std::vector<float> f = floats_of(old, comps);
    const std::size_t count = f.size() / comps, elem = static_cast<std::size_t>(comps * bytes);
    const std::size_t stride = (elem + 3) / 4 * 4;  // vertex attributes are 4-byte aligned
    g.bin.append((4 - g.bin.size() % 4) % 4, '\0');
    const std::size_t at = g.bin.size();
    std::string data(count * stride, '\0');
    const double levels = is_signed ? (bytes == 1 ? 127.0 : 32767.0) : (bytes == 1 ? 255.0 : 65535.0);
    for (std::size_t i = 0; i < count; ++i)
      for (int c = 0; c < comps; ++c) {
        const long q = std::lround(to_unit(f[i * comps + c], c) * levels);
        std::memcpy(&data[i * stride + c * bytes], &q, bytes);  // little-endian low bytes
      }
    g.bin += data;
    g.gltf["bufferViews"].push_back(
        {{"buffer", 0}, {"byteOffset", at}, {"byteLength", data.size()}, {"byteStride", stride}});
    const int component = is_signed ? (bytes == 1 ? 5120 : 5122) : (bytes == 1 ? 5121 : 5123);
    g.gltf["accessors"].push_back({{"bufferView", g.gltf["bufferViews"].size() - 1},
                                   {"componentType", component},
                                   {"normalized", true},
                                   {"count", count},
                                   {"type", comps == 1 ? "SCALAR" : (comps == 3 ? "VEC3" : "VEC4")}});
    attrs[name] = g.gltf["accessors"].size() - 1;
  };
  const json& pos = g.gltf["accessors"][attrs["POSITION"].get<int>()];
  double centre[3], half = 0;
  for (int c = 0; c < 3; ++c) {
    centre[c] = 0.5 * (pos["min"][c].get<double>() + pos["max"][c].get<double>());
    half = std::max(half, 0.5 * (pos["max"][c].get<double>() - pos["min"][c].get<double>()));
  }
  quantize("POSITION", 3, true, 2, [&](float v, int c) { return (v - centre[c]) / half; });
  quantize(ext + "ROTATION", 4, true, 2, [](float v, int) { return v; });
  quantize(ext + "OPACITY", 1, false, 1, [](float v, int) { return v; });
  g.gltf["nodes"][0]["translation"] = {centre[0], centre[1], centre[2]};
  g.gltf["nodes"][0]["scale"] = {half, half, half};
  // The node's scale scales each Gaussian too (a similarity transform scales its covariance), so
  // the stored SCALE attribute (floats) is divided by it, in place.
  {
    const json& a = g.gltf["accessors"][attrs[ext + "SCALE"].get<int>()];
    const json& v = g.gltf["bufferViews"][a["bufferView"].get<int>()];
    const std::size_t at = v["byteOffset"].get<std::size_t>() + a.value("byteOffset", std::size_t{0});
    for (std::size_t i = 0; i < 3 * a["count"].get<std::size_t>(); ++i) {
      float f;
      std::memcpy(&f, &g.bin[at + 4 * i], 4);
      f = static_cast<float>(f / half);
      std::memcpy(&g.bin[at + 4 * i], &f, 4);
    }
  }
  g.gltf["extensionsUsed"].push_back("KHR_mesh_quantization");
  g.gltf["extensionsRequired"] = {"KHR_mesh_quantization"};
  g.gltf["buffers"][0]["byteLength"] = g.bin.size();
  write_glb(dir + "/quantized.glb", g);
  const GaussianModel ours = load_scene(dir + "/quantized.glb"), reference = load_scene(plain);
  ASSERT_EQ(ours.size(), reference.size());
  const double psnr = test::min_render_psnr(ours, reference, test::comparison_views(reference));
  std::cout << "[ info ] biker .glb with int16 centres and rotations and uint8 opacities: " << psnr
            << " dB against the float .glb\n";
  EXPECT_GE(psnr, kSameDb);
}

// Base64 (RFC 4648, with padding) for a data URI.
std::string base64(const std::string& bytes) {
  static const char* const kDigits = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  for (std::size_t i = 0; i < bytes.size(); i += 3) {
    uint32_t v = static_cast<uint32_t>(static_cast<uint8_t>(bytes[i])) << 16;
    if (i + 1 < bytes.size()) v |= static_cast<uint32_t>(static_cast<uint8_t>(bytes[i + 1])) << 8;
    if (i + 2 < bytes.size()) v |= static_cast<uint8_t>(bytes[i + 2]);
    out += kDigits[(v >> 18) & 63];
    out += kDigits[(v >> 12) & 63];
    out += i + 1 < bytes.size() ? kDigits[(v >> 6) & 63] : '=';
    out += i + 2 < bytes.size() ? kDigits[v & 63] : '=';
  }
  return out;
}

// The glTF JSON as a text .gltf: "asset" and "extensionsUsed" first (as glTF writers put them;
// format detection by content looks for KHR_gaussian_splatting in a file's first 4 KiB), then
// the rest in the .glb's order, with buffers[0] read from `uri`. `buffers_first`: the buffers
// first instead, so a data URI pushes every mention of the extension past those 4 KiB (the file's
// .gltf name must decide).
std::string gltf_text(const json& gltf, const std::string& uri, bool buffers_first = false) {
  nlohmann::ordered_json out;
  if (buffers_first) out["buffers"] = json::array({{{"byteLength", gltf["buffers"][0]["byteLength"]}, {"uri", uri}}});
  out["asset"] = gltf["asset"];
  out["extensionsUsed"] = gltf["extensionsUsed"];
  for (const auto& [key, value] : gltf.items())
    if (key != "asset" && key != "extensionsUsed") out[key] = value;
  out["buffers"][0]["uri"] = uri;
  return out.dump();
}

// A text .gltf (glTF 2.0 section 4.3: JSON, buffers named by URI), made from splat-transform's .glb
// of the bundled biker with its binary chunk as an external .bin file and as a base64 data URI,
// reads as the .glb does: the same Gaussians, bit for bit, and the same renders.
TEST(GltfText, ExternalAndDataUriBuffersReadAsTheGlb) {
  CATGS_REQUIRE_SPLAT_TRANSFORM();
  const std::string dir = test::temp_dir(), plain = dir + "/biker.glb";
  ASSERT_EQ(test::splat_transform(test::bundled_scene(), plain), "");
  const Glb g = read_glb(plain);
  ASSERT_EQ(g.gltf["buffers"].size(), 1u);
  // The BIN chunk is padded to 4 bytes; a URI's bytes must be the buffer's byteLength exactly.
  const std::string bin = g.bin.substr(0, g.gltf["buffers"][0]["byteLength"].get<std::size_t>());
  test::write_bytes(dir + "/biker.bin", bin);
  test::write_bytes(dir + "/external.gltf", gltf_text(g.gltf, "biker.bin"));
  const std::string data_uri = "data:application/octet-stream;base64," + base64(bin);
  test::write_bytes(dir + "/inline.gltf", gltf_text(g.gltf, data_uri));
  const std::string late = gltf_text(g.gltf, data_uri, /*buffers_first=*/true);
  ASSERT_GT(late.find("KHR_gaussian_splatting"), 4096u) << "the extension must be named past 4 KiB";
  test::write_bytes(dir + "/late_extension.gltf", late);
  const GaussianModel glb = load_scene(plain);
  for (const std::string name : {"external.gltf", "inline.gltf", "late_extension.gltf"}) {
    const GaussianModel text = load_scene(dir + "/" + name);
    ASSERT_EQ(text.size(), glb.size()) << name;
    EXPECT_EQ(text.sh_degree, glb.sh_degree) << name;
    EXPECT_EQ(text.means, glb.means) << name;
    EXPECT_EQ(text.rotations, glb.rotations) << name;
    EXPECT_EQ(text.log_scales, glb.log_scales) << name;
    EXPECT_EQ(text.opacity_logits, glb.opacity_logits) << name;
    EXPECT_EQ(text.sh, glb.sh) << name;
    const double psnr = test::min_render_psnr(text, glb, test::comparison_views(glb));
    std::cout << "[ info ] " << name << " vs the .glb: " << psnr << " dB (identical renders: 1e9)\n";
    EXPECT_GE(psnr, 1e9) << name;
  }
}

}  // namespace
