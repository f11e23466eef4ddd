// AOVs (engine/aov.h, docs/outputs.md): albedo, normal and depth, carried by the sample buffer,
// merged by passes and written as EXR layers.
#include <gtest/gtest.h>

#include <cmath>

#include "engine/buffer_file.h"
#include "engine/buffer_merge.h"
#include "engine/digest.h"
#include "engine/render.h"
#include "engine/shapes.h"
#include "engine/formats/mesh_placement.h"
#include "tests/support/fixtures.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

TEST(Aov, ListsParseInAnyOrderToOneCanonicalText) {
  EXPECT_EQ(to_string(parse_aovs("depth,albedo")), "albedo,depth");
  EXPECT_EQ(to_string(parse_aovs("normal,depth,albedo")), "albedo,normal,depth");
  EXPECT_FALSE(parse_aovs("").any());
  EXPECT_EQ(parse_aovs("albedo,normal,depth").channels(), 9);
  EXPECT_EQ(test::error_of([] { parse_aovs("albedo,colour"); }),
            "unknown AOV 'colour' (known: albedo, normal, depth)");
  EXPECT_EQ(test::error_of([] { parse_aovs("depth,depth"); }), "AOV 'depth' is listed twice");
  EXPECT_EQ(test::error_of([] { parse_aovs("albedo,"); }),
            "unknown AOV '' (known: albedo, normal, depth)");
}

// A diffuse square of reflectance (0.2, 0.5, 0.7) facing the camera 2 units away, covering the
// left half of an 8x8 image (x < 0 in world space); the right half sees nothing.
Scene square_scene() {
  Material m;
  m.reflectance.value = RGB{0.2f, 0.5f, 0.7f};
  Mesh square;
  place_mesh(make_rectangle(), Mat4::translate({-1, 0, 0}), "test", "square", square);
  Scene s = test::make_scene({m}, {square}, {0, 0, 2}, {0, 0, 0}, 8, 8, "aov-square");
  s.render.spp = 8;
  s.render.passes = 2;
  s.render.aovs = parse_aovs("albedo,normal,depth");
  return s;
}

SampleBuffer render_all_passes(const Renderer& r) {
  const Scene& s = r.scene();
  SampleBuffer frame(r.header(0, PassSet{}), Rect{0, 0, s.film.width, s.film.height}, r.splats());
  for (uint32_t pass = 0; pass < s.render.passes; ++pass)
    merge_into(frame, r.render(TaskKey{0, Rect{0, 0, s.film.width, s.film.height}, pass}, true));
  return frame;
}

// Exact: every sample of a pixel inside the square hits the same flat diffuse surface, so the
// albedo and normal means equal the reflectance and the facing normal up to float rounding.
TEST(Aov, DiffuseSurfaceAlbedoIsItsReflectance) {
  Scene s = square_scene();
  Renderer r(s);
  SampleBuffer frame = render_all_passes(r);
  ASSERT_EQ(frame.aov.size(), 64u * 9u);
  float coverage = -1;
  AovSample in = frame.aov_mean(1, 4, &coverage);  // left half: the square
  EXPECT_FLOAT_EQ(in.albedo.x, 0.2f);
  EXPECT_FLOAT_EQ(in.albedo.y, 0.5f);
  EXPECT_FLOAT_EQ(in.albedo.z, 0.7f);
  EXPECT_NEAR(in.normal.z, 1.0f, 1e-6f);
  EXPECT_EQ(coverage, 1.0f);
  // Camera distance of a point of the plane z = 0 seen from (0, 0, 2): 2 / cos(angle to the axis).
  EXPECT_GT(in.depth, 2.0f);
  EXPECT_LT(in.depth, 2.0f / std::cos(0.5f * 40.0f * kPi / 180.0f) * 1.01f);
  AovSample out = frame.aov_mean(6, 4, &coverage);  // right half: a miss
  EXPECT_EQ(coverage, 0.0f);
  EXPECT_FALSE(out.hit);
  EXPECT_EQ(out.albedo.x, 0.0f);
  EXPECT_EQ(out.normal.z, 0.0f);
}

TEST(Aov, CornellLeftWallAlbedoIsItsReflectance) {
  test::CornellBox settings;
  settings.res = 16;
  settings.passes = 1;
  Scene s = test::cornell_box(settings);
  s.render.aovs = parse_aovs("albedo");
  const Material* left = nullptr;
  for (const Material& m : s.materials)
    if (m.name == "LeftWall") left = &m;
  ASSERT_NE(left, nullptr);
  Renderer r(s);
  SampleBuffer frame = render_all_passes(r);
  AovSample a = frame.aov_mean(1, 8, nullptr);  // the red wall, left edge, mid height
  for (int c = 0; c < 3; ++c) EXPECT_FLOAT_EQ(a.albedo[c], left->reflectance.value[c]) << c;
}

// A mirror beside the square, facing the camera, and a second diffuse square behind the camera
// facing the mirror: the right half of the image sees that square in the mirror, so its albedo is
// the square's reflectance times the mirror's (tint mode: the tint), and its normal the square's.
TEST(Aov, MirrorsPassTheAlbedoBehindThemTinted) {
  Scene s = square_scene();
  Material mirror;
  mirror.type = MaterialType::Conductor;
  mirror.conductor_tint = true;
  mirror.specular.value = RGB{0.5f, 0.5f, 0.5f};
  s.materials.push_back(mirror);
  Mesh m, back;
  place_mesh(make_rectangle(), Mat4::translate({1, 0, 0}), "test", "mirror", m);
  m.material = 1;
  place_mesh(make_rectangle(),
             Mat4::translate({0, 0, 3}) * Mat4::rotate({0, 1, 0}, 180) * Mat4::scale({5, 5, 1}),
             "test", "back", back);
  s.meshes.push_back(m);
  s.meshes.push_back(back);
  Renderer r(s);
  SampleBuffer frame = render_all_passes(r);
  for (int y = 2; y < 6; ++y)
    for (int x = 5; x < 8; ++x) {
      AovSample a = frame.aov_mean(x, y, nullptr);
      EXPECT_NEAR(a.albedo.x, 0.1f, 1e-6f) << x << "," << y;
      EXPECT_NEAR(a.albedo.y, 0.25f, 1e-6f) << x << "," << y;
      EXPECT_NEAR(a.albedo.z, 0.35f, 1e-6f) << x << "," << y;
      EXPECT_NEAR(a.normal.z, -1.0f, 1e-5f);  // the back square's, facing the reflected ray
      EXPECT_NEAR(a.depth, 2.0f, 0.2f);       // depth is the mirror's distance
    }
}

// The AOV plane merges by passes like the image: two passes merged equal the one-render frame
// within the merge tolerance, and buffers with different AOV sets do not merge.
TEST(Aov, PassesMergeAndDifferentSetsDoNot) {
  Scene s = square_scene();
  Renderer r(s);
  SampleBuffer a = render_all_passes(r);
  SampleBuffer b = render_all_passes(r);
  ASSERT_EQ(a.aov, b.aov);  // deterministic
  Scene other = s;
  other.render.aovs = parse_aovs("albedo");
  Renderer r2(other);
  SampleBuffer c = r2.render(TaskKey{0, Rect{0, 0, 8, 8}, 0}, false);
  SampleBuffer d = r.render(TaskKey{0, Rect{0, 0, 8, 8}, 1}, false);
  EXPECT_NE(test::error_of([&] { merge_into(c, d); }).find("aovs differs: \"albedo\" vs \"albedo,normal,depth\""),
            std::string::npos);
}

// Light tracing has no camera path: its AOVs come from camera rays cast for them, started like
// the path tracer's camera samples, so the two AOV planes are bit-identical.
TEST(Aov, LightTracingCastsCameraRaysForItsAovs) {
  test::CornellBox settings;
  settings.res = 12;
  settings.passes = 1;
  Scene path = test::cornell_box(settings);
  path.render.aovs = parse_aovs("albedo,normal,depth");
  Scene light = path;
  light.render.integrator.method = LightIntegrator{};
  Renderer rp(path), rl(light);
  SampleBuffer bp = rp.render(TaskKey{0, Rect{0, 0, 12, 12}, 0}, true);
  SampleBuffer bl = rl.render(TaskKey{0, Rect{0, 0, 12, 12}, 0}, true);
  ASSERT_EQ(bp.aov.size(), bl.aov.size());
  EXPECT_EQ(bp.aov, bl.aov);
}

TEST(Aov, BufferFilesCarryTheAovsAndVersionOneStillReads) {
  Scene s = square_scene();
  Renderer r(s);
  SampleBuffer a = r.render(TaskKey{0, Rect{0, 0, 8, 8}, 0}, false);
  SampleBuffer back = decode_buffer(encode_buffer(a), "a.rfb");
  EXPECT_EQ(back.header.aovs, a.header.aovs);
  EXPECT_EQ(back.aov, a.aov);
  // A version 1 file: no AOV key or plane. Made from a buffer without AOVs, relabelled and
  // re-checksummed.
  Scene plain = square_scene();
  plain.render.aovs = AovSet{};
  Renderer rp(plain);
  std::string bytes = encode_buffer(rp.render(TaskKey{0, Rect{0, 0, 8, 8}, 0}, false));
  bytes.resize(bytes.size() - test::rfb_checksum_bytes(3));
  SampleBuffer v1 = decode_buffer(test::rfb_with_checksum(bytes, 1), "v1.rfb");
  EXPECT_FALSE(v1.header.aovs.any());
  EXPECT_TRUE(v1.aov.empty());
}

// The CLI writes the AOVs as EXR layers with standard channel names (oiiotool lists them).
TEST(Aov, ExrListsTheLayers) {
  std::string dir = test::make_temp_dir("aov-exr");
  auto run = test::run_command(test::rayfarm_binary() + " render " + test::source_dir() +
                               "/scenes/cornell-box/scene.json --res 16x16 --spp 4 --passes 2 "
                               "--aov depth,normal,albedo -q -o " + dir + "/out.exr");
  ASSERT_EQ(run.exit_code, 0) << run.output;
  auto info = test::run_command("oiiotool --info -v " + dir + "/out.exr");
  ASSERT_EQ(info.exit_code, 0) << info.output;
  // OpenEXR stores channels sorted by name; every one must be listed.
  size_t list = info.output.find("channel list:");
  ASSERT_NE(list, std::string::npos) << info.output;
  std::string channels = info.output.substr(list, info.output.find('\n', list) - list) + ",";
  for (const char* c : {" R,", " G,", " B,", " A,", " variance.R,", " variance.G,", " variance.B,",
                        " albedo.R,", " albedo.G,", " albedo.B,", " N.X,", " N.Y,", " N.Z,", " Z,",
                        " coverage,"})
    EXPECT_NE(channels.find(c), std::string::npos) << c << " missing from" << channels;
  EXPECT_NE(info.output.find("15 channel"), std::string::npos) << info.output;
  EXPECT_NE(info.output.find("rayfarm:aovs: \"albedo,normal,depth\""), std::string::npos) << info.output;
  auto bad = test::run_command(test::rayfarm_binary() + " render " + test::source_dir() +
                               "/scenes/cornell-box/scene.json --aov alpha -q -o " + dir + "/bad.exr");
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_NE(bad.output.find("--aov: unknown AOV 'alpha'"), std::string::npos) << bad.output;
}

}  // namespace
}  // namespace rf
