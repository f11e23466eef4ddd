// What an integrator module is (docs/adding-an-integrator.md). Each integrator is a struct in its
// own NAME.h, with its settings (parse, settings_text, check) in NAME_settings.cpp (the scene
// library) and its estimator (render) in NAME.cpp (the renderer). The struct holds its parameters
// as plain data and says, in this shape:
//
//   struct FooIntegrator : IntegratorDefaults {
//     static constexpr const char* kName = "foo";       // render.integrator.type, --integrator
//     static constexpr bool kSplats = false;            // whole-frame splatting tasks, or tiles
//     static constexpr const char* kKeys[] = {"type", "max_depth", "rr_min_depth", "bar"};
//     // optional: static constexpr int kFixedMaxDepth = 1;  (max_depth is not a parameter)
//     float bar = 1;                                     // its own parameters, with defaults
//     void parse(const JsonReader&, const Json&, const std::string& path);  // its own keys
//     std::string settings_text() const;                 // appended to the buffer header's
//     void check(const Scene&) const;                    // throws SceneError if it cannot render
//     // optional: kNeedsLights, kPbrtTypes, kMitsubaTypes, kMovingGeometry, from_pbrt,
//     // from_mitsuba (below)
//     SampleBuffer render(const RenderContext&, const TaskKey&, bool parallel) const;
//     bool operator==(const FooIntegrator&) const = default;
//   };
//
// render() runs one of the two drivers (drivers.h) with the integrator's estimator, and prepares
// per-pass state (RenderContext::pass_cache) first if it has any. registry.h lists the structs in
// one std::variant; dispatch is one std::visit per task, never a virtual call per sample.
// This header is included by scene.h, so it and the integrator headers declare and forward-declare
// only: their definitions live in the .cpp files.
#pragma once

#include <nlohmann/json_fwd.hpp>
#include <string>

namespace rf {

using Json = nlohmann::json;
class JsonReader;
struct Scene;
struct RenderContext;
struct TaskKey;
struct SampleBuffer;
struct Ray;
class Sampler;
struct TraceCounters;

// An imported scene's integrator parameters (pbrt-v4's `Integrator` directive, Mitsuba 3's
// <integrator>), read by the module's own mapping (from_pbrt, from_mitsuba). Each importer adapts
// its parameter list: a read marks the parameter used (the importer warns of the rest), a value
// of the wrong type and fail() are SceneErrors naming the file and line.
class ForeignParams {
 public:
  virtual ~ForeignParams() = default;
  virtual int integer(const std::string& name, int fallback) const = 0;
  virtual double number(const std::string& name, double fallback) const = 0;
  virtual bool boolean(const std::string& name, bool fallback) const = 0;
  [[noreturn]] virtual void fail(const std::string& message) const = 0;
};

// Members an integrator without parameters, restrictions or imported names need not write.
struct IntegratorDefaults {
  // Whether an image without lights is black (a warning says so); ambient occlusion needs none.
  static constexpr bool kNeedsLights = true;
  // The integrator types of other renderers' scenes that map to this one, space-separated:
  // pbrt-v4 `Integrator` names and Mitsuba 3 <integrator type> names.
  static constexpr const char* kPbrtTypes = "";
  static constexpr const char* kMitsubaTypes = "";
  // Whether it renders moving geometry (geometry_moves): estimators that build per-pass state
  // shared by camera samples at every time of the shutter (ir's virtual point lights, ppm's
  // photons) would gather light from where the geometry was at another time.
  static constexpr bool kMovingGeometry = true;

  void parse(const JsonReader&, const Json&, const std::string&) {}
  std::string settings_text() const { return {}; }
  void check(const Scene&) const {}
  // The imported scene's parameters of this integrator (depths are the importer's: common to all).
  void from_pbrt(const ForeignParams&) {}
  void from_mitsuba(const ForeignParams&) {}
};

}  // namespace rf
