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

// Members an integrator without parameters or restrictions need not write.
struct IntegratorDefaults {
  void parse(const JsonReader&, const Json&, const std::string&) {}
  std::string settings_text() const { return {}; }
  void check(const Scene&) const {}
};

}  // namespace rf
