// glTF's metallic-roughness material onto the engine's materials (docs/formats/gltf.md,
// "Materials"): metallic -> rough conductor with Schlick F0 = base colour; dielectric -> plastic
// (GGX coat, IOR 1.5 or KHR_materials_ior, over a diffuse base = base colour), or Lambertian when
// the surface has no specular (roughness 1 untextured, KHR_materials_specular factor 0, IOR 1);
// transmission -> thin or solid dielectric. GGX alpha = roughness^2 (glTF's perceptual roughness).
#include <algorithm>
#include <cmath>

#include "engine/formats/gltf/gltf_internal.h"
#include "engine/fresnel.h"
#include "engine/json_reader.h"
#include "engine/microfacet.h"

namespace rf::gltf {
namespace {

// Material extensions this importer reads, fully or in part; others are named in a warning.
const std::vector<std::string> kReadMaterialExtensions = {
    "KHR_materials_emissive_strength", "KHR_materials_ior", "KHR_materials_transmission",
    "KHR_materials_volume", "KHR_materials_specular"};

double number_in(const Context& c, const json& obj, const std::string& key, double fallback,
                 double lo, double hi, const std::string& where) {
  auto it = obj.find(key);
  if (it == obj.end()) return fallback;
  if (!it->is_number()) c.fail(ptr(where, key), "expected a number");
  double v = it->get<double>();
  if (!(v >= lo && v <= hi))
    c.fail(ptr(where, key), "must be in [" + format_number(lo) + ", " + format_number(hi) +
                                "], got " + format_number(v));
  return v;
}

RGB factor_rgb(const Context& c, const std::vector<double>& f, size_t n, double hi,
               const std::string& where) {
  if (f.size() != n)
    c.fail(where, "expected " + std::to_string(n) + " numbers, got " + std::to_string(f.size()));
  float v[3];
  for (size_t i = 0; i < 3; ++i) {
    // Exporters round: a factor up to 0.1% above the limit is the limit.
    if (!(f[i] >= 0 && f[i] <= hi * 1.001))
      c.fail(ptr(where, i),
             "must be in [0, " + format_number(hi) + "], got " + format_number(f[i]));
    v[i] = float(std::min(f[i], hi));
  }
  for (size_t i = 3; i < n; ++i)
    if (!(f[i] >= 0 && f[i] <= 1.001))
      c.fail(ptr(where, i), "must be in [0, 1], got " + format_number(f[i]));
  return RGB(v[0], v[1], v[2]);
}

// What a textureInfo's texture reads, as a Scene::textures entry with the remapping the role
// needs (factor, channel, squared). uv: glTF's v runs down from the top-left; meshes store
// v' = 1 - v (the engine's v runs up), and KHR_texture_transform's scale s and offset o become
// uv_scale = s, uv_offset = (o.x, 1 - s.y - o.y) in that flipped space.
struct TextureRole {
  bool is_data = false;
  RGB scale{1.0f};
  int8_t channel = -1;
  bool squared = false;
};

int32_t add_texture(Context& c, const tinygltf::TextureInfo& info, const std::string& where,
                    const TextureRole& role) {
  const auto& m = c.model;
  if (info.index < 0 || size_t(info.index) >= m.textures.size())
    c.fail(ptr(where, "index"), "texture " + std::to_string(info.index) +
                                    " does not exist (the file has " +
                                    std::to_string(m.textures.size()) + ")");
  const std::string tp = ptr("/textures", size_t(info.index));
  const tinygltf::Texture& gt = m.textures[size_t(info.index)];
  if (gt.source < 0)
    c.fail(ptr(tp, "source"),
           "the texture has no source image this importer reads (PNG or JPEG; "
           "KHR_texture_basisu and EXT_texture_webp are not read)");
  if (info.texCoord != 0)
    c.warn(ptr(where, "texCoord"), "TEXCOORD_" + std::to_string(info.texCoord) +
                                       " is not read: the texture is looked up with TEXCOORD_0");
  if (gt.sampler != -1) {
    if (gt.sampler < 0 || size_t(gt.sampler) >= m.samplers.size())
      c.fail(ptr(tp, "sampler"), "sampler " + std::to_string(gt.sampler) + " does not exist");
    const tinygltf::Sampler& s = m.samplers[size_t(gt.sampler)];
    if (s.wrapS != TINYGLTF_TEXTURE_WRAP_REPEAT || s.wrapT != TINYGLTF_TEXTURE_WRAP_REPEAT)
      c.warn(ptr("/samplers", size_t(gt.sampler)),
             "wrap modes CLAMP_TO_EDGE and MIRRORED_REPEAT are not supported: the texture repeats");
  }
  Texture t;
  t.name = where;
  t.type = TextureType::Image;
  t.resolved_path = image_file(c, gt.source, ptr(tp, "source"));
  t.file = t.resolved_path;
  t.is_data = role.is_data;
  t.scale = role.scale;
  t.channel = role.channel;
  t.squared = role.squared;
  Vec2 s{1, 1}, o{0, 0};
  const std::string xp = ptr(ptr(where, "extensions"), "KHR_texture_transform");
  if (const json* x = c.extension(where, "KHR_texture_transform")) {
    auto vec2 = [&](const char* key, Vec2 fallback) {
      auto it = x->find(key);
      if (it == x->end()) return fallback;
      if (!it->is_array() || it->size() != 2 || !(*it)[0].is_number() || !(*it)[1].is_number())
        c.fail(ptr(xp, key), "expected two numbers");
      Vec2 v{(*it)[0].get<float>(), (*it)[1].get<float>()};
      if (!std::isfinite(v.x) || !std::isfinite(v.y)) c.fail(ptr(xp, key), "must be finite");
      return v;
    };
    s = vec2("scale", s);
    o = vec2("offset", o);
    if (number_in(c, *x, "rotation", 0, -1e9, 1e9, xp) != 0)
      c.warn(ptr(xp, "rotation"), "texture rotation is not supported (ignored)");
    if (x->contains("texCoord"))
      c.warn(ptr(xp, "texCoord"), "texCoord override is not read: TEXCOORD_0 is used");
  }
  t.uv_scale = s;
  t.uv_offset = {o.x, 1.0f - s.y - o.y};
  c.scene->textures.push_back(std::move(t));
  return int32_t(c.scene->textures.size() - 1);
}

// The plastic's diffuse albedo is (1 - F(cos_o)) R (1 - F_dr) / (1 - R F_dr), F_dr its coat's
// internal diffuse reflectance (engine/bsdfs/plastic.h); glTF's dielectric BRDF weighs its
// Lambertian lobe by (1 - F) baseColor. R = b / ((1 - F_dr) + b F_dr), per channel, makes them
// equal (R <= 1 for b <= 1); without it the base would render 30-60% too dark at IOR 1.5.
RGB coat_compensated(RGB b, float ior) {
  const float fdr = fresnel_diffuse_reflectance_interior(ior);
  RGB r;
  for (int k = 0; k < 3; ++k) r[k] = b[k] / ((1 - fdr) + b[k] * fdr);
  return r;
}

// glTF's default material (a primitive without one): base colour 1, metallic 1, roughness 1.
Material default_material() {
  Material m;
  m.name = "(glTF default material)";
  m.type = MaterialType::RoughConductor;
  m.conductor_tint = true;
  m.specular.value = RGB(1.0f);
  m.roughness.value = 1.0f;
  return m;
}

struct Converted {
  Material material;
  std::optional<Emission> emission;
};

Converted convert(Context& c, size_t index, MaterialMap& out) {
  const tinygltf::Material& gm = c.model.materials[index];
  const std::string p = ptr("/materials", index);
  const std::string pbrp = ptr(p, "pbrMetallicRoughness");
  const tinygltf::PbrMetallicRoughness& pbr = gm.pbrMetallicRoughness;
  Converted r;
  Material& m = r.material;
  m.name = gm.name.empty() ? p : gm.name;

  // Base colour (alpha: see alphaMode) and the optional texture it multiplies.
  RGB base = factor_rgb(c, pbr.baseColorFactor, 4, 1, ptr(pbrp, "baseColorFactor"));
  ColorParam base_param{base};
  if (pbr.baseColorTexture.index >= 0 || c.at(ptr(pbrp, "baseColorTexture"))) {
    TextureRole role;
    role.scale = base;
    base_param.texture = add_texture(c, pbr.baseColorTexture, ptr(pbrp, "baseColorTexture"), role);
    out.uses_texcoord = true;
  }
  const double metallic = pbr.metallicFactor, rough = pbr.roughnessFactor;
  if (!(metallic >= 0 && metallic <= 1))
    c.fail(ptr(pbrp, "metallicFactor"), "must be in [0, 1], got " + format_number(metallic));
  if (!(rough >= 0 && rough <= 1))
    c.fail(ptr(pbrp, "roughnessFactor"), "must be in [0, 1], got " + format_number(rough));
  const bool mr_texture =
      pbr.metallicRoughnessTexture.index >= 0 || c.at(ptr(pbrp, "metallicRoughnessTexture"));
  // GGX alpha = (roughnessFactor * G)^2: roughness is the texture's green channel.
  FloatParam alpha{float(rough * rough)};
  if (mr_texture) {
    TextureRole role;
    role.is_data = true, role.scale = RGB(float(rough)), role.channel = 1, role.squared = true;
    alpha.texture =
        add_texture(c, pbr.metallicRoughnessTexture, ptr(pbrp, "metallicRoughnessTexture"), role);
    out.uses_texcoord = true;
  }
  const bool metal = metallic >= 0.5;
  if (mr_texture && metallic > 0)
    c.warn(ptr(pbrp, "metallicRoughnessTexture"),
           "metallic (the texture's blue channel) cannot vary over a surface: the whole material "
           "is a " +
               std::string(metal ? "metal" : "dielectric") + " by metallicFactor " +
               format_number(metallic) + " (roughness, green, is read per texel)");
  else if (metallic > 0 && metallic < 1)
    c.warn(ptr(pbrp, "metallicFactor"),
           "in-between metallic " + format_number(metallic) + " is not blended: rendered as a " +
               (metal ? "metal (metallic 1)" : "dielectric (metallic 0)"));

  // Extensions.
  const json* ior_ext = c.extension(p, "KHR_materials_ior");
  double ior = ior_ext ? number_in(c, *ior_ext, "ior", 1.5, 0, 10,
                                   ptr(ptr(p, "extensions"), "KHR_materials_ior"))
                       : 1.5;
  if (ior != 0 && ior < 1)
    c.fail(ptr(ptr(ptr(p, "extensions"), "KHR_materials_ior"), "ior"), "must be 0 or >= 1");
  if (ior == 0) ior = 1e9;  // the spec's "infinite IOR"; clamped below
  double specular = 1;
  if (const json* x = c.extension(p, "KHR_materials_specular")) {
    const std::string xp = ptr(ptr(p, "extensions"), "KHR_materials_specular");
    specular = number_in(c, *x, "specularFactor", 1, 0, 1, xp);
    if (x->contains("specularColorFactor") || x->contains("specularTexture") ||
        x->contains("specularColorTexture") || (specular > 0 && specular < 1))
      c.warn(xp,
             "only specularFactor 0 (no specular: Lambertian) or 1 is represented; the "
             "specular colour, textures and in-between factors are ignored");
  }
  double transmission = 0;
  if (const json* x = c.extension(p, "KHR_materials_transmission")) {
    const std::string xp = ptr(ptr(p, "extensions"), "KHR_materials_transmission");
    transmission = number_in(c, *x, "transmissionFactor", 0, 0, 1, xp);
    if (x->contains("transmissionTexture"))
      c.warn(ptr(xp, "transmissionTexture"),
             "not read: transmission is transmissionFactor throughout");
  }
  double thickness = 0;
  if (const json* x = c.extension(p, "KHR_materials_volume")) {
    const std::string xp = ptr(ptr(p, "extensions"), "KHR_materials_volume");
    thickness = number_in(c, *x, "thicknessFactor", 0, 0, 1e30, xp);
    if (x->contains("attenuationColor") || x->contains("attenuationDistance"))
      c.warn(xp, "volume attenuation is not supported: the medium inside is clear");
  }
  if (const json* exts = c.at(ptr(p, "extensions")); exts && exts->is_object())
    for (auto it = exts->begin(); it != exts->end(); ++it)
      if (!contains_name(kReadMaterialExtensions, it.key()))
        c.warn(ptr(ptr(p, "extensions"), it.key()), "material extension not supported (ignored)");

  const float engine_ior = float(std::min(std::max(ior, 1.01), 3.99));
  if (engine_ior != float(ior) && ior != 1.0)
    c.warn(ptr(ptr(ptr(p, "extensions"), "KHR_materials_ior"), "ior"),
           "IOR " + format_number(ior) + " clamped to " + format_number(engine_ior) +
               " (the engine's range is (1, 4))");
  if (transmission > 0 && !metal) {
    if (transmission < 1)
      c.warn(ptr(ptr(ptr(p, "extensions"), "KHR_materials_transmission"), "transmissionFactor"),
             "partial transmission " + format_number(transmission) +
                 " is rendered as full transmission (a dielectric)");
    m.ior = ior == 1.0 ? 1.01f : engine_ior;
    m.specular = base_param;  // the base colour tints what is transmitted
    if (thickness > 0) {      // a solid: the volume extension gives it an inside
      m.type = MaterialType::RoughDielectric;
      m.roughness = alpha;
      if (!mr_texture && alpha.value < kSmoothAlpha) m.type = MaterialType::Dielectric;
    } else {  // thin-walled, as the spec treats transmission without a volume
      m.type = MaterialType::ThinDielectric;
      if (mr_texture || alpha.value >= kSmoothAlpha)
        c.warn(ptr(pbrp, "roughnessFactor"),
               "rough thin-walled transmission is not supported: rendered smooth (a thin "
               "dielectric); add KHR_materials_volume for a rough solid");
    }
  } else if (metal) {
    m.type = MaterialType::RoughConductor;
    m.conductor_tint = true;  // Schlick Fresnel with F0 = base colour
    m.specular = base_param;
    m.roughness = alpha;
  } else if ((!mr_texture && rough == 1.0) || specular == 0 || ior == 1.0) {
    m.type = MaterialType::Diffuse;  // no specular lobe worth a coat
    m.reflectance = base_param;
  } else if (base_param.texture >= 0) {
    // The coat's compensation (below) is not linear in the base colour, so it cannot follow a
    // texture; an uncompensated plastic would be 30-60% too dark, so keep the albedo instead.
    m.type = MaterialType::Diffuse;
    m.reflectance = base_param;
    c.warn(ptr(pbrp, "baseColorTexture"),
           "a textured dielectric is rendered Lambertian (its specular coat, roughness " +
               format_number(rough) + ", is dropped to keep the textured colour's albedo)");
  } else {
    m.type = MaterialType::Plastic;
    m.reflectance.value = coat_compensated(base, engine_ior);
    m.roughness = alpha;
    m.ior = engine_ior;
  }

  // alphaMode, normal maps, occlusion.
  if (gm.alphaMode == "MASK" || gm.alphaMode == "BLEND")
    c.warn(ptr(p, "alphaMode"), gm.alphaMode + " is not supported: the surface is opaque");
  else if (gm.alphaMode != "OPAQUE")
    c.fail(ptr(p, "alphaMode"), "unknown alphaMode '" + gm.alphaMode + "'");
  if (gm.normalTexture.index >= 0)
    c.warn(ptr(p, "normalTexture"),
           "normal maps are not supported (ignored: the shading "
           "normals are the mesh's)");
  // occlusionTexture: deliberately ignored, a path tracer computes occlusion.

  // Emission: radiance = emissiveFactor x KHR_materials_emissive_strength, on the front side
  // (both sides when doubleSided).
  RGB emissive =
      factor_rgb(c, gm.emissiveFactor.empty() ? std::vector<double>{0, 0, 0} : gm.emissiveFactor, 3,
                 1e30, ptr(p, "emissiveFactor"));
  if (const json* x = c.extension(p, "KHR_materials_emissive_strength"))
    emissive =
        emissive * float(number_in(c, *x, "emissiveStrength", 1, 0, 1e30,
                                   ptr(ptr(p, "extensions"), "KHR_materials_emissive_strength")));
  if (gm.emissiveTexture.index >= 0)
    c.warn(ptr(p, "emissiveTexture"),
           "emissive textures are not supported: the surface emits emissiveFactor" +
               std::string(is_black(emissive) ? " (black: no light)" : " uniformly"));
  if (!is_black(emissive)) {
    if (!std::isfinite(emissive.x) || !std::isfinite(emissive.y) || !std::isfinite(emissive.z))
      c.fail(ptr(p, "emissiveFactor"), "emission is not finite");
    r.emission = Emission{emissive, gm.doubleSided};
  }
  return r;
}

}  // namespace

MaterialMap convert_materials(Context& c) {
  MaterialMap out;
  for (size_t i = 0; i < c.model.materials.size(); ++i) {
    Converted m = convert(c, i, out);
    out.material.push_back(uint32_t(c.scene->materials.size()));
    out.emission.push_back(m.emission);
    c.scene->materials.push_back(std::move(m.material));
  }
  out.default_material = uint32_t(c.scene->materials.size());
  c.scene->materials.push_back(default_material());
  return out;
}

}  // namespace rf::gltf
