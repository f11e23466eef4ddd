// The pbrt-v4 importer's state while it reads a scene: the graphics state and its stack, named
// coordinate systems, materials, textures and objects, and the Scene being filled. Directives are
// in pbrt_scene.cpp, shapes in pbrt_geometry.cpp, materials and textures in pbrt_materials.cpp.
#pragma once

#include <cstring>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "engine/formats/pbrt/pbrt_parser.h"
#include "engine/formats/scene_files.h"
#include "engine/json_reader.h"
#include "engine/scene.h"

namespace rf::pbrt {

struct AreaLight {
  RGB L{1.0f};
  float scale = 1;
  bool two_sided = false;
  double power = -1;  // > 0: pbrt-v4's "power" (W) per shape
  Location at;
};

struct GraphicsState {
  // pbrt-v4's pair of current transforms: at TransformTimes' start and end. ActiveTransform picks
  // which of them the transform directives change; a shape or instance whose two differ moves.
  Mat4 ctm, ctm_end;
  bool moving() const { return std::memcmp(&ctm, &ctm_end, sizeof(Mat4)) != 0; }
  bool reverse_orientation = false;
  int material = -1;          // index into Builder::materials_, -1: pbrt's default (diffuse 0.5)
  std::string material_name;  // NamedMaterial's name (takes precedence over `material`)
  Location material_at;       // of that NamedMaterial
  std::optional<AreaLight> area_light;
  Location begun_at;  // of the AttributeBegin that saved this state
};

// A material as defined: the engine's material, or why it cannot be one (an error only once a
// shape uses it), or pbrt's "interface" (no surface: the shape is left out).
struct MaterialDef {
  Material material;
  std::string error;
  bool interface = false;
  Location at;
  int32_t scene_index = -1;  // in Scene::materials once a shape uses it
};

// A texture reference resolved: a constant, or a texture in Scene::textures.
struct TexValue {
  RGB value{0.0f};
  int32_t texture = -1;
};

class Builder {
 public:
  Builder(const std::string& path, Scene& scene, SceneFiles& files);
  void run(const std::string& main_bytes);

  // Used by the material and shape code.
  void warn(const Location& at, const std::string& what);
  void warn_unused(const ParamList& params, const std::string& directive);
  RGB spectrum_value(const Param& p, bool illuminant, const std::string& directive);
  std::vector<double> read_spd(const Param& p, const std::string& file,
                               const std::string& directive);

 private:
  enum class Active { All, Start, End };

  void directive(const std::string& name, Lexer& lex, const Location& at);
  void finish();
  std::string string_arg(Lexer& lex, const std::string& directive);
  std::vector<double> number_args(Lexer& lex, const std::string& directive, size_t n);
  Mat4 look_at(const Location& at, const std::vector<double>& v);
  void include(Lexer& lex, const Location& at, const std::string& directive);

  void camera(const std::string& type, const ParamList& params, const Location& at);
  // The current transform pair as a motion: start at transform_times_[0], end at [1] (map's
  // transform applied to each first); throws SceneError naming `at` for a singular key.
  AnimatedTransform ctm_motion(const Location& at, const std::string& what,
                               const Mat4& after = Mat4::identity()) const;
  void film(const std::string& type, const ParamList& params, const Location& at);
  void filter(const std::string& type, const ParamList& params, const Location& at);
  void sampler(const std::string& type, const ParamList& params, const Location& at);
  void integrator(const std::string& type, const ParamList& params, const Location& at);

  RGB light_spectrum(const ParamList& params, const std::string& name, const Location& at,
                     const std::string& directive);
  void light(const std::string& type, const ParamList& params, const Location& at);
  void infinite_light(const ParamList& params, const Location& at, float scale);
  void area_light(const std::string& type, const ParamList& params, const Location& at);

  // pbrt_geometry.cpp
  void shape(const std::string& type, const ParamList& params, const Location& at);
  MeshData shape_mesh(const std::string& type, const ParamList& params, const Location& at,
                      std::vector<uint32_t>& element_of_triangle, bool& whole_shape);
  // Radius of the shape being added when it is a whole pbrt sphere (0 otherwise): placed as an
  // exact sphere when its transform is a similarity and its orientation not reversed.
  float exact_sphere_radius_ = 0;
  void add_mesh(MeshData data, const std::vector<uint32_t>& element_of_triangle, bool whole_shape,
                const std::string& type, const Location& at, uint32_t material);

  // pbrt_materials.cpp
  int define_material(const std::string& name, const std::string& type, const ParamList& params,
                      const Location& at);
  MaterialDef build_material(const std::string& type, const ParamList& params,
                             const std::string& d);
  // The current material's index in Scene::materials; `pending` when it is a NamedMaterial not
  // defined yet (resolve_pending_materials() sets it once the whole file is read).
  uint32_t material_for_shape(const Location& at, const std::string& shape, bool& interface,
                              bool& pending);
  uint32_t use_material(int index, const Location& at, const std::string& shape, bool& interface);
  void resolve_pending_materials();
  ColorParam color_param(const ParamList& params, const std::string& name, RGB def,
                         const std::string& d);
  FloatParam float_param(const ParamList& params, const std::string& name, float def,
                         const std::string& d);
  FloatParam roughness(const ParamList& params, const std::string& prefix, const std::string& d);
  float ior_value(const ParamList& params, const std::string& name, const std::string& d);
  void texture(const std::string& name, const std::string& kind, const std::string& cls,
               const ParamList& params, const Location& at);
  TexValue tex_input(const ParamList& params, const std::string& name, RGB def, bool is_float,
                     const std::string& d);
  int32_t push_texture(Texture t);

  // Runs a SceneFiles call and rethrows its error as "<file>:<line>: <what>: ...".
  template <class F>
  auto files_call(const Location& at, const std::string& what, F f) -> decltype(f()) {
    try {
      return f();
    } catch (const SceneError& e) {
      std::string msg = e.what();
      const std::string prefix = path_ + ": ";
      if (msg.compare(0, prefix.size(), prefix) == 0) msg = msg.substr(prefix.size());
      fail(at, what + ": " + msg);
    }
  }

  std::string path_;
  Scene& scene_;
  SceneFiles& files_;
  std::vector<std::unique_ptr<Lexer>> lexers_;  // the include stack, innermost last
  GraphicsState gs_;
  std::vector<GraphicsState> stack_;
  std::vector<std::pair<Mat4, Mat4>> transform_stack_;
  Active active_ = Active::All;
  double transform_times_[2] = {0, 1};  // TransformTimes
  std::map<std::string, std::pair<Mat4, Mat4>> named_coords_;
  std::vector<MaterialDef> materials_;
  std::map<std::string, int> named_materials_;
  int default_material_ = -1;
  struct PendingMaterial {
    int object;   // -1: Scene::meshes, else Scene::objects[object].meshes
    size_t mesh;  // index in that list
    std::string name;
    Location material_at, shape_at;
    std::string shape;
  };
  std::vector<PendingMaterial> pending_materials_;
  std::map<std::string, TexValue> float_textures_, spectrum_textures_;
  std::map<int32_t, std::pair<float, bool>> image_arith_;  // image texture -> baked (scale, invert)
  std::map<std::string, uint32_t> object_ids_;
  std::vector<std::vector<Light>> object_lights_;  // per object, in object space
  int current_object_ = -1;
  Location object_begin_at_;
  Location cur_at_;
  double exposure_time_ = 1,
         iso_ = 100;  // the sensor's imaging ratio: exposure_time * iso / 100  // the directive
                      // being read (for messages about its parameters)
};

}  // namespace rf::pbrt
