// The pbrt-v4 importer (docs/formats/pbrt.md): every supported directive over small hand-written
// files in tests/data/pbrt/, one malformed file per kind of error (the message names the file,
// the line and the problem), and agreement with the JSON versions of the shipped scenes through
// the statistics harness.
#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "engine/envmap.h"
#include "engine/formats/importers.h"
#include "engine/formats/pbrt/pbrt_envmap.h"
#include "engine/formats/pbrt/pbrt_spectra.h"
#include "engine/local_render.h"
#include "engine/render.h"
#include "engine/scene.h"
#include "tests/support/harness.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

std::string data(const std::string& f) { return test::source_dir() + "/tests/data/pbrt/" + f; }

bool has_warning(const Scene& s, const std::string& part) {
  for (const std::string& w : s.warnings)
    if (w.find(part) != std::string::npos) return true;
  return false;
}

const Material& material_named(const Scene& s, const std::string& name) {
  for (const Material& m : s.materials)
    if (m.name == name) return m;
  throw std::runtime_error("no material " + name);
}

void expect_near(Vec3 a, Vec3 b, float tol) {
  EXPECT_NEAR(a.x, b.x, tol);
  EXPECT_NEAR(a.y, b.y, tol);
  EXPECT_NEAR(a.z, b.z, tol);
}

// ---------------------------------------------------------------------------------------------
// Directives

TEST(PbrtDirectives, SettingsCameraAndWarnings) {
  Scene s = load_scene(data("directives.pbrt"));
  EXPECT_EQ(s.film.width, 48);
  EXPECT_EQ(s.film.height, 32);
  EXPECT_EQ(s.film.filter.type, FilterType::Triangle);
  EXPECT_FLOAT_EQ(s.film.filter.radius, 1.5f);
  EXPECT_EQ(s.render.spp, 24u);
  EXPECT_EQ(s.render.passes, default_passes(24));  // 4
  EXPECT_EQ(s.render.seed, 3u);
  EXPECT_EQ(s.render.sampler, "sobol");
  EXPECT_EQ(s.render.integrator.type(), "bdpt");
  EXPECT_EQ(s.render.integrator.max_depth, 7);
  EXPECT_FLOAT_EQ(s.camera.fov_deg, 30);
  EXPECT_FLOAT_EQ(s.camera.lens_radius, 0.05f);
  EXPECT_FLOAT_EQ(s.camera.focus_distance, 5);
  // pbrt's LookAt frame is left-handed: camera +x is cross(up, dir) = world -x here, so the image
  // is the mirror of a right-handed look-at (pbrt renders it so).
  const Mat4& c = s.camera.camera_to_world;
  expect_near(c.point({0, 0, 0}), {0, 1, 5}, 1e-5f);
  expect_near(c.vector({0, 0, -1}), {0, 0, -1}, 1e-5f);
  expect_near(c.vector({1, 0, 0}), {-1, 0, 0}, 1e-5f);
  expect_near(c.vector({0, 1, 0}), {0, 1, 0}, 1e-5f);
  // Unsupported directives and parameters are warnings naming file:line and the directive.
  EXPECT_TRUE(has_warning(s, "directives.pbrt:2: Option \"bool disablepixeljitter\""));
  EXPECT_TRUE(has_warning(s, "directives.pbrt:12: Attribute \"shape\""));
  EXPECT_TRUE(has_warning(s, "directives.pbrt:13: MakeNamedMedium \"fog\""));
  EXPECT_TRUE(has_warning(s, "MakeNamedMaterial \"aniso\": anisotropic roughness"));
  EXPECT_TRUE(has_warning(s, "frosted\": \"spectrum eta\" \"glass-BK7\": dispersion"));
  EXPECT_TRUE(has_warning(s, "geometry.pbrt:11: Shape \"sphere\": its material (\"interface\")"));
  EXPECT_FALSE(has_warning(s, "filename"));  // Film's output name is the command line's business
}

TEST(PbrtDirectives, MaterialsAndTextures) {
  Scene s = load_scene(data("directives.pbrt"));
  const Material& floor = material_named(s, "floor");
  EXPECT_EQ(floor.type, MaterialType::Diffuse);
  ASSERT_GE(floor.reflectance.texture, 0);
  const Texture& checks = s.textures[size_t(floor.reflectance.texture)];
  EXPECT_EQ(checks.type, TextureType::Checkerboard);
  expect_near(checks.color_a, {0.8f, 0.1f, 0.1f}, 0);
  EXPECT_EQ(checks.uv_scale.x, 4);
  EXPECT_EQ(checks.uv_scale.y, 8);
  const Material& plastic = material_named(s, "plastic");
  EXPECT_EQ(plastic.type, MaterialType::Plastic);
  EXPECT_FLOAT_EQ(plastic.roughness.value, 0.01f);  // remaproughness false: alpha as given
  EXPECT_FLOAT_EQ(plastic.ior, 1.5f);
  const Material& glass = material_named(s, "glass");
  EXPECT_EQ(glass.type, MaterialType::Dielectric);
  EXPECT_FLOAT_EQ(glass.ior, 1.33f);
}

TEST(PbrtDirectives, MaterialsOnlyOnceUsed) {
  // Only materials a shape uses reach the scene; their values follow pbrt-v4's definitions.
  Scene s = load_scene(data("directives.pbrt"));
  std::vector<std::string> names;
  for (const Material& m : s.materials) names.push_back(m.name);
  EXPECT_EQ(names, (std::vector<std::string>{"floor", "plastic", "glass", "mirror", "gold"}));
  const Material& gold = material_named(s, "gold");
  EXPECT_EQ(gold.type, MaterialType::RoughConductor);
  EXPECT_FLOAT_EQ(gold.roughness.value, 0.2f);  // remapped: sqrt(0.04)
  expect_near(gold.eta, conductor_preset("gold")->eta, 0);
  expect_near(gold.k, conductor_preset("gold")->k, 0);
  EXPECT_EQ(material_named(s, "mirror").type, MaterialType::Conductor);  // alpha 0: smooth
}

TEST(PbrtDirectives, LightsAndAreaLights) {
  Scene s = load_scene(data("directives.pbrt"));
  // point (in the "lamp" coordinate system), spot, distant, then the two instances' points.
  ASSERT_EQ(s.lights.size(), 5u);
  const Light& point = s.lights[0];
  EXPECT_EQ(point.type, LightType::Point);
  expect_near(point.position, {0, 0.5f, 0}, 1e-6f);
  expect_near(point.intensity, {2, 4, 6}, 1e-6f);  // I * scale
  const Light& spot = s.lights[1];
  EXPECT_EQ(spot.type, LightType::Spot);
  expect_near(spot.direction, {0, -1, 0}, 1e-6f);
  EXPECT_FLOAT_EQ(spot.cone_angle_deg, 40);
  EXPECT_FLOAT_EQ(spot.falloff_start_deg, 30);
  // power: I = power / (2 pi ((1 - cos 30) + (cos 30 - cos 40) / 2)) for a blackbody of
  // luminance 1.
  double k =
      2 * M_PI * ((1 - std::cos(M_PI / 6)) + (std::cos(M_PI / 6) - std::cos(40 * M_PI / 180)) / 2);
  EXPECT_NEAR(luminance(spot.intensity), 10 / k, 0.02 * 10 / k);  // the CIE fit's luminance: ~1%
  const Light& distant = s.lights[2];
  EXPECT_EQ(distant.type, LightType::Directional);
  expect_near(distant.direction, {0, -1, 0}, 1e-6f);
  expect_near(distant.irradiance, {2, 2, 2}, 0);
  // The instances' lights: the object's light at the origin moved by each instance.
  expect_near(s.lights[3].position, {1, 0, 0}, 1e-6f);
  expect_near(s.lights[4].position, {-1, 0, 0}, 1e-6f);
  ASSERT_TRUE(s.environment.has_value());
  EXPECT_TRUE(s.environment->file.empty());
  expect_near(s.environment->scale, {0.1f, 0.2f, 0.3f}, 0);

  // The area light quad: power 100 W, two-sided, area 0.5 per triangle (pbrt-v4: a light per
  // triangle): L = 4 * 100 / (pi * 0.5 * 2).
  int area_lights = 0;
  for (const Mesh& m : s.meshes) {
    if (!m.emission) continue;
    ++area_lights;
    if (m.emission->two_sided) {
      expect_near(m.emission->radiance, RGB(float(400 / M_PI)), 1e-3f);
      // ReverseOrientation without normals flips the winding: -y as written, +y reversed.
      Vec3 n = cross(m.positions[m.indices[1]] - m.positions[m.indices[0]],
                     m.positions[m.indices[2]] - m.positions[m.indices[0]]);
      EXPECT_GT(n.y, 0);
    } else {
      EXPECT_NEAR(luminance(m.emission->radiance), 3, 0.05);  // blackbody: luminance 1, scale 3
    }
  }
  EXPECT_EQ(area_lights, 2);
}

TEST(PbrtDirectives, ShapesIncludesAndInstances) {
  Scene s = load_scene(data("directives.pbrt"));
  // Meshes: floor, bilinear patch, PLY quad, (interface sphere left out), area quad, emitting
  // sphere, the disk in camera space, then 2 instances x 1 half-hemisphere (kept as Embree
  // instances by load_scene; flattened here to check their placement).
  ASSERT_EQ(s.instances.size(), 2u);
  flatten_instances(s);
  ASSERT_EQ(s.meshes.size(), 8u);
  EXPECT_EQ(s.meshes[1].triangle_count(), 2u);  // a planar bilinear patch is exact as 2 triangles
  EXPECT_EQ(s.meshes[2].triangle_count(), 2u);  // the PLY's quad, fanned
  // The disk: CoordSysTransform "camera" puts it 1 in front of the camera (pbrt's +z).
  const Mesh& disk = s.meshes[5];
  Vec3 centre(0.0f);
  for (const Vec3& p : disk.positions) centre = centre + p;
  centre = centre / float(disk.positions.size());
  expect_near(centre, {0, 1, 4}, 2e-3f);
  // The instanced partial sphere (zmin 0, phimax 180): a quarter sphere, radius 0.25 in object
  // space, scaled by 2 in the second instance.
  float max_r0 = 0, max_r1 = 0;
  for (const Vec3& p : s.meshes[6].positions) max_r0 = std::max(max_r0, length(p - Vec3(1, 0, 0)));
  for (const Vec3& p : s.meshes[7].positions) max_r1 = std::max(max_r1, length(p - Vec3(-1, 0, 0)));
  EXPECT_NEAR(max_r0, 0.25f, 1e-5f);
  EXPECT_NEAR(max_r1, 0.5f, 1e-5f);
  for (const Vec3& p : s.meshes[6].positions) {
    EXPECT_GE(p.z, -1e-6f);  // zmin 0
    EXPECT_GE(p.y, -1e-6f);  // phi in [0, 180]: y >= 0
  }
  // The included files are assets (they ship with the farm bundle).
  EXPECT_EQ(s.assets, (std::vector<std::string>{"inc/geometry.pbrt", "inc/quad.ply"}));
}

TEST(PbrtDirectives, InstancesStayObjectsUntilLoadSceneFlattens) {
  Scene s = import_scene(data("directives.pbrt"));
  ASSERT_EQ(s.objects.size(), 1u);
  EXPECT_EQ(s.objects[0].name, "post");
  ASSERT_EQ(s.instances.size(), 2u);
  expect_near(s.instances[1].to_world.vector({1, 0, 0}), {0, 0, -2},
              1e-5f);  // Rotate 90 y, Scale 2
}

TEST(PbrtDirectives, NamedMaterialsMayBeDefinedLater) {
  Scene s = load_scene(data("forward.pbrt"));
  ASSERT_EQ(s.meshes.size(), 1u);  // the disk's material is "interface": left out
  ASSERT_EQ(s.materials.size(), 1u);
  EXPECT_EQ(s.materials[0].name, "late");
  EXPECT_EQ(s.materials[0].type, MaterialType::Conductor);
  EXPECT_EQ(s.meshes[0].material, 0u);
  EXPECT_TRUE(has_warning(s, "forward.pbrt:7: its material (\"interface\")"));
}

TEST(PbrtDirectives, AreaLightPowerIsPerTriangleAsInPbrtV4) {
  // Triangles of area 0.5 and 1 under "power" 10: pbrt-v4 makes one light per triangle, each of
  // 10 W, so L = 10 / (pi A): two meshes of radiance 20/pi and 10/pi.
  std::string dir = test::make_temp_dir("pbrt-power");
  test::write_text(dir + "/scene.pbrt",
                   "WorldBegin\nAreaLightSource \"diffuse\" \"rgb L\" [1 1 1] \"float power\" 10\n"
                   "Shape \"trianglemesh\" \"point3 P\" [0 0 0 1 0 0 0 1 0  2 0 0 4 0 0 2 1 0]\n"
                   "  \"integer indices\" [0 1 2 3 4 5]\n");
  Scene s = load_scene(dir + "/scene.pbrt");
  ASSERT_EQ(s.meshes.size(), 2u);
  std::vector<float> L = {s.meshes[0].emission->radiance.x, s.meshes[1].emission->radiance.x};
  std::sort(L.begin(), L.end());
  EXPECT_NEAR(L[0], 10 / M_PI, 1e-4);
  EXPECT_NEAR(L[1], 20 / M_PI, 1e-4);
}

TEST(PbrtDirectives, SensorImagingRatioScalesEveryEmitter) {
  // pbrt-v4's cie1931 sensor multiplies the image by exposure time x ISO / 100 = 0.5 x 400 / 100.
  std::string dir = test::make_temp_dir("pbrt-iso");
  test::write_text(
      dir + "/scene.pbrt",
      "Film \"rgb\" \"float iso\" 400\nCamera \"perspective\" \"float shutterclose\" 0.5\n"
      "WorldBegin\nLightSource \"point\" \"rgb I\" [1 2 3]\nLightSource \"infinite\" \"rgb L\" [1 "
      "1 1]\n"
      "AttributeBegin\nAreaLightSource \"diffuse\" \"rgb L\" [4 4 4]\nShape "
      "\"disk\"\nAttributeEnd\n");
  Scene s = load_scene(dir + "/scene.pbrt");
  expect_near(s.lights.at(0).intensity, {2, 4, 6}, 1e-6f);
  expect_near(s.environment->scale, {2, 2, 2}, 1e-6f);
  ASSERT_TRUE(s.meshes.at(0).emission.has_value());
  expect_near(s.meshes[0].emission->radiance, {8, 8, 8}, 1e-6f);
}

// ---------------------------------------------------------------------------------------------
// Colour and maps

TEST(PbrtSpectra, BlackbodyAndNamedSpectra) {
  // 6504 K is near D65 but not on it (D65 lies 0.005 above the Planckian locus in CIE y), so a
  // 6504 K blackbody of luminance 1 is white within 6% per channel (slightly magenta).
  expect_near(pbrt::blackbody_rgb(6504), RGB(1.0f), 0.06f);
  RGB warm = pbrt::blackbody_rgb(2700);
  EXPECT_GT(warm.x, warm.y);
  EXPECT_GT(warm.y, warm.z);
  EXPECT_NEAR(luminance(warm), 1.0f,
              0.02f);  // normalised to luminance 1 (the fit's Y vs Rec.709's)
  // A flat reflectance spectrum is grey.
  expect_near(pbrt::sampled_spectrum_rgb({400, 0.3, 700, 0.3}, false), RGB(0.3f), 1e-4f);
  EXPECT_EQ(*pbrt::named_spectrum_rgb("metal-Cu-eta", false), conductor_preset("copper")->eta);
  EXPECT_FALSE(pbrt::named_spectrum_rgb("metal-CuZn-eta", false).has_value());
}

TEST(PbrtSpectra, SpectrumFilesAndInlineSpectra) {
  Scene s = load_scene(data("spectra.pbrt"));
  ASSERT_EQ(s.materials.size(), 1u);
  expect_near(s.materials[0].eta, RGB(0.5f), 1e-4f);  // flat spectra are grey
  expect_near(s.materials[0].k, RGB(3.0f), 1e-3f);
  EXPECT_EQ(s.assets, std::vector<std::string>{"inc/flat.spd"});  // shipped with the scene
}

TEST(PbrtEnvmap, EqualAreaOctahedralSquare) {
  // pbrt-v4's mapping: +z at the centre, -z at the corners, +x at the right edge's middle.
  Vec2 c = pbrt::equal_area_square({0, 0, 1});
  EXPECT_NEAR(c.x, 0.5f, 1e-6f);
  EXPECT_NEAR(c.y, 0.5f, 1e-6f);
  Vec2 x = pbrt::equal_area_square({1, 0, 0});
  EXPECT_NEAR(x.x, 1.0f, 1e-6f);
  EXPECT_NEAR(x.y, 0.5f, 1e-6f);
  Vec2 y = pbrt::equal_area_square({0, 1, 0});
  EXPECT_NEAR(y.x, 0.5f, 1e-6f);
  EXPECT_NEAR(y.y, 1.0f, 1e-6f);
  Vec2 down = pbrt::equal_area_square({0, 0, -1});
  EXPECT_NEAR(std::fabs(down.x - 0.5f), 0.5f, 1e-6f);
  EXPECT_NEAR(std::fabs(down.y - 0.5f), 0.5f, 1e-6f);
}

TEST(PbrtEnvmap, ImageInfiniteLightIsResampledToLatLong) {
  // A 32x32 octahedral map: 1 on the light's upper hemisphere (the square's inner diamond) and 0.1
  // below, x2 where light-space x > 0 (right half), x1.5 where y > 0 (bottom half: pbrt's row 0 is
  // the top). `Rotate -90 1 0 0` takes light (x, y, z) to world (x, z, -y).
  const int n = 32;
  std::vector<float> px(size_t(n) * n * 3);
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      float u = 2 * (x + 0.5f) / n - 1, v = 2 * (y + 0.5f) / n - 1;
      float value = (std::fabs(u) + std::fabs(v) < 1 ? 1.0f : 0.1f) * (u > 0 ? 2.0f : 1.0f) *
                    (v > 0 ? 1.5f : 1.0f);
      for (int c = 0; c < 3; ++c) px[(size_t(y) * n + x) * 3 + c] = value;
    }
  std::string dir = test::make_temp_dir("pbrt-env");
  auto out = OIIO::ImageOutput::create(dir + "/sky.exr");
  ASSERT_TRUE(out && out->open(dir + "/sky.exr", OIIO::ImageSpec(n, n, 3, OIIO::TypeDesc::FLOAT)));
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, px.data()) && out->close());
  test::write_text(dir + "/scene.pbrt",
                   "WorldBegin\nAttributeBegin\nRotate -90 1 0 0\n"
                   "LightSource \"infinite\" \"string filename\" \"sky.exr\" \"float scale\" 3\n"
                   "AttributeEnd\n");
  Scene s = load_scene(dir + "/scene.pbrt");
  ASSERT_TRUE(s.environment.has_value());
  EXPECT_EQ(s.environment->file, "sky.exr");
  EXPECT_EQ(s.assets, std::vector<std::string>{"sky.exr"});
  EnvironmentMap map(*s.environment);
  EXPECT_EQ(map.width(), 2 * n);
  EXPECT_EQ(map.height(), n);
  // Exact away from the diamond's edges (each lat-long texel averages 16 lookups).
  EXPECT_FLOAT_EQ(map.radiance(normalize(Vec3(0.3f, 1, 0.2f))).x, 6.0f);   // light (+x, -y, +z)
  EXPECT_FLOAT_EQ(map.radiance(normalize(Vec3(-0.3f, 1, 0.2f))).x, 3.0f);  // light (-x, -y, +z)
  EXPECT_FLOAT_EQ(map.radiance(normalize(Vec3(0.3f, 1, -0.2f))).x, 9.0f);  // light (+x, +y, +z)
  EXPECT_FLOAT_EQ(map.radiance(normalize(Vec3(0.3f, -1, 0.2f))).x, 0.6f);  // light (+x, -y, -z)
}

// Reads the first channel of an image's pixels as float.
std::vector<float> first_channel(const std::string& path) {
  auto in = OIIO::ImageInput::open(path);
  if (!in) return {};
  const OIIO::ImageSpec& spec = in->spec();
  std::vector<float> px(size_t(spec.width) * spec.height * spec.nchannels);
  in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, px.data());
  std::vector<float> out;
  for (size_t i = 0; i < px.size(); i += size_t(spec.nchannels)) out.push_back(px[i]);
  return out;
}

TEST(PbrtTextures, ImageScaleAndInvertAreBakedIntoACopy) {
  // An 8-bit PNG (sRGB by pbrt-v4's default for .png): texels 255 and 128.
  std::string dir = test::make_temp_dir("pbrt-tex");
  unsigned char px[2 * 3] = {255, 255, 255, 128, 128, 128};
  auto out = OIIO::ImageOutput::create(dir + "/t.png");
  ASSERT_TRUE(out && out->open(dir + "/t.png", OIIO::ImageSpec(2, 1, 3, OIIO::TypeDesc::UINT8)));
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, px) && out->close());
  test::write_text(
      dir + "/scene.pbrt",
      "WorldBegin\nTexture \"a\" \"spectrum\" \"imagemap\" \"string filename\" \"t.png\" \"float "
      "scale\" 0.5\n"
      "Texture \"b\" \"spectrum\" \"scale\" \"texture tex\" \"a\" \"float scale\" 0.5\n"
      "Texture \"c\" \"spectrum\" \"imagemap\" \"string filename\" \"t.png\" \"bool invert\" "
      "true\n");
  Scene s = load_scene(dir + "/scene.pbrt");
  ASSERT_EQ(s.textures.size(), 3u);
  EXPECT_EQ(s.assets, std::vector<std::string>{"t.png"});  // the original ships, not the copies
  const float dark = 0.21586f;                             // sRGB 128/255 decoded
  std::vector<float> a = first_channel(s.textures[0].resolved_path),
                     b = first_channel(s.textures[1].resolved_path),
                     c = first_channel(s.textures[2].resolved_path);
  ASSERT_EQ(a.size(), 2u);
  ASSERT_EQ(b.size(), 2u);
  ASSERT_EQ(c.size(), 2u);
  EXPECT_NEAR(a[0], 0.5f, 1e-5f);
  EXPECT_NEAR(a[1], 0.5f * dark, 1e-4f);
  EXPECT_NEAR(b[0], 0.25f, 1e-5f);
  EXPECT_NEAR(b[1], 0.25f * dark, 1e-4f);
  EXPECT_NEAR(c[0], 0.0f, 1e-5f);
  EXPECT_NEAR(c[1], 1 - dark, 1e-4f);
}

// ---------------------------------------------------------------------------------------------
// Malformed files: each message starts "<file>:<line>: " and says what is wrong.

struct BadFile {
  const char* file;
  int line;
  const char* what;
};

class PbrtBadFile : public testing::TestWithParam<BadFile> {};

TEST_P(PbrtBadFile, MessageNamesFileLineAndProblem) {
  const BadFile& bad = GetParam();
  std::string path = data(std::string("bad/") + bad.file);
  try {
    load_scene(path);
    FAIL() << "loaded without error";
  } catch (const SceneError& e) {
    std::string msg = e.what();
    std::string where = path + ":" + std::to_string(bad.line) + ": ";
    if (std::string(bad.file) == "include_chain.pbrt") where = data("bad/inner.pbrt") + ":2: ";
    EXPECT_EQ(msg.rfind(where, 0), 0u) << msg;
    EXPECT_NE(msg.find(bad.what), std::string::npos) << msg;
  }
}

INSTANTIATE_TEST_SUITE_P(
    Pbrt, PbrtBadFile,
    testing::Values(
        BadFile{"unterminated_string.pbrt", 3, "unterminated string"},
        BadFile{"missing_bracket.pbrt", 4, "\"integer indices\": ']' expected before \"point3 P\""},
        BadFile{"unknown_shape.pbrt", 3, "Shape \"teapot\": unknown shape"},
        BadFile{"unknown_material.pbrt", 3,
                "Shape \"sphere\": Material \"velvet\": material type \"velvet\" is unknown"},
        BadFile{"bad_param_type.pbrt", 2, "unknown parameter type 'floot'"},
        BadFile{"include_missing.pbrt", 2, "'nothere.pbrt' not found"},
        BadFile{"include_outside.pbrt", 2, "'..' not allowed"},
        BadFile{"attribute_end.pbrt", 4, "AttributeEnd without a matching AttributeBegin"},
        BadFile{"unknown_object.pbrt", 4, "ObjectInstance: unknown object \"tree\""},
        BadFile{"transform_count.pbrt", 1, "Transform: expected 16 numbers, got 12"},
        BadFile{"include_chain.pbrt", 2, "\"float radius\": expected a number, got 'big'"},
        BadFile{"unsupported_shape.pbrt", 2, "Shape \"curve\": shape not supported"},
        BadFile{"unknown_directive.pbrt", 2, "unknown directive 'WorldBgin'"},
        BadFile{"camera_type.pbrt", 1, "Camera \"orthographic\": only the perspective camera"},
        BadFile{"bad_bool.pbrt", 2, "\"bool twosided\": expected true or false, got 'yes'"},
        BadFile{"unknown_named_material.pbrt", 3,
                "Shape \"sphere\": material \"chrome\" (NamedMaterial at "},
        BadFile{"index_range.pbrt", 3, "index 3 out of range (3 vertices)"},
        BadFile{"unknown_spectrum.pbrt", 2, "unknown named spectrum \"metal-CuZn-eta\""}),
    [](const auto& info) {
      std::string n = info.param.file;
      return n.substr(0, n.find('.'));
    });

TEST(PbrtBadFile, IncludeChainIsNamed) {
  try {
    load_scene(data("bad/include_chain.pbrt"));
    FAIL();
  } catch (const SceneError& e) {
    EXPECT_NE(
        std::string(e.what()).find("(included from " + data("bad/include_chain.pbrt") + ":3)"),
        std::string::npos)
        << e.what();
  }
}

// ---------------------------------------------------------------------------------------------
// Agreement with the JSON scenes (the statistics harness: per-pixel Welch t tests at level 0.001
// with a binomial allowance of outliers, and image means within 1%).

Scene load_with(const std::string& path, int w, int h, int max_depth, uint64_t spp, uint32_t passes,
                const char* filter, const char* sampler = "independent", uint64_t seed = 1) {
  SceneOverrides ov;
  ov.width = w, ov.height = h, ov.max_depth = max_depth, ov.spp = spp, ov.passes = passes;
  ov.filter = filter;
  ov.sampler = sampler;
  ov.seed = seed;
  ov.integrator = "path";
  return load_scene(path, ov);
}

TEST(PbrtAgreement, CornellBoxMatchesTheJsonScene) {
  // 64x64, box filter, 32 passes of 4 spp. Max depth 16 rather than 64: the walls' albedo <= 0.73
  // leaves (0.73)^16 = 0.6% of the light beyond depth 16 in either render alike, and it halves
  // the time; the depth-64 means are checked below. Both renders use seed 1 (common random
  // numbers, as in the Veach MIS test below): each image mean's own standard error (~0.4%) would
  // make the harness's 1% check fail a correct render about one time in 50; the per-pixel t tests
  // are only made conservative by the correlation.
  const std::string dir = test::source_dir() + "/scenes/cornell-box/";
  Scene pbrt = load_with(dir + "scene-v4.pbrt", 64, 64, 16, 128, 32, "box");
  Scene json = load_with(dir + "scene.json", 64, 64, 16, 128, 32, "box");
  EXPECT_FLOAT_EQ(pbrt.film.filter.radius, 0.5f);
  test::Agreement a =
      test::compare(test::render_stats(pbrt, 32, 1), test::render_stats(json, 32, 1));
  EXPECT_TRUE(a.passed) << a.message;
  std::printf("cornell pbrt vs json: %s\n", a.message.c_str());
}

TEST(PbrtAgreement, CornellBoxImageMeansMatchTheReference) {
  // The converged means at max depth 64 (tests/cornell_test.cpp): (0.1963, 0.1275, 0.0361), each
  // within 1%; 64x64 at 1024 spp puts the render's own standard error below 0.2% of each.
  SceneOverrides ov;
  ov.width = 64, ov.height = 64, ov.max_depth = 64, ov.spp = 1024, ov.passes = 16,
  ov.filter = "box";
  Scene s = load_scene(test::source_dir() + "/scenes/cornell-box/scene-v4.pbrt", ov);
  Renderer r(s);
  LocalRenderResult res = render_local(r, {});
  test::expect_cornell_means(test::image_means(res.frame), 0.002, "Cornell box (pbrt)");
}

// Both at 160x90 (the shipped 1280x720 and 640x360 scaled down), triangle filter of radius 1
// and max depth 3 (both files'), 32 passes.
void veach_mis_agreement(uint64_t spp_per_pass, const char* sampler, uint64_t seed_pbrt,
                         uint64_t seed_json) {
  const std::string dir = test::source_dir() + "/scenes/veach-mis/";
  Scene pbrt = load_with(dir + "scene-v4.pbrt", 160, 90, 3, 32 * spp_per_pass, 32, "triangle",
                         sampler, seed_pbrt);
  Scene json = load_with(dir + "scene.json", 160, 90, 3, 32 * spp_per_pass, 32, "triangle", sampler,
                         seed_json);
  EXPECT_FLOAT_EQ(pbrt.film.filter.radius, 1.0f);
  EXPECT_FLOAT_EQ(json.film.filter.radius, 1.0f);
  test::Agreement a =
      test::compare(test::render_stats(pbrt, 32, 1), test::render_stats(json, 32, 1));
  EXPECT_TRUE(a.passed) << a.message;
  std::printf("veach-mis pbrt vs json: %s\n", a.message.c_str());
}

TEST(PbrtAgreement, VeachMisMatchesTheJsonScene) {
  // The image mean is dominated by sub-pixel, very bright features (the r = 0.05 light of
  // radiance 3039 and its reflections), so at 4 spp per pass each render's mean has a standard
  // error of ~1.4%, too much for the harness's independent 1% check. Both renders therefore use
  // the same seed (common random numbers): the same camera samples see the same lights, so the
  // two means differ by far less than their own errors (0.18% measured), while the per-pixel t
  // tests stay valid (correlation between the renders only makes them conservative). The
  // independent comparison with 16x the samples is LongPbrtAgreement's.
  veach_mis_agreement(4, "independent", 1, 1);
}

TEST(LongPbrtAgreement, VeachMisMatchesTheJsonSceneIndependently) {
  // Independent seeds; Owen-scrambled sobol at 64 spp per pass brings each mean's standard error
  // to ~0.25%.
  veach_mis_agreement(64, "sobol", 1, 2);
}

TEST(PbrtSmoke, VeachBidirLoadsAndRenders) {
  SceneOverrides ov;
  ov.width = 32, ov.height = 32, ov.spp = 4, ov.passes = 1;
  Scene s = load_scene(test::source_dir() + "/scenes/veach-bidir/scene-v4.pbrt", ov);
  EXPECT_EQ(s.render.integrator.type(), "bdpt");
  EXPECT_EQ(s.render.integrator.max_depth, 7);
  EXPECT_EQ(s.meshes.size(), 14u);  // 12 PLY meshes and 2 area-light quads
  int lights = 0;
  for (const Mesh& m : s.meshes) lights += m.emission ? 1 : 0;
  EXPECT_EQ(lights, 2);
  Renderer r(s);
  LocalRenderResult res = render_local(r, {});
  RGB mean = res.frame.mean_estimate();
  EXPECT_TRUE(std::isfinite(mean.x) && std::isfinite(mean.y) && std::isfinite(mean.z));
  EXPECT_GT(luminance(mean), 0);
}

}  // namespace
}  // namespace rf
