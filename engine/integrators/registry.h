// The closed list of integrators (docs/adding-an-integrator.md). Each is a struct in its own
// NAME.h with NAME_settings.cpp and NAME.cpp (module.h says what they hold); adding one is those
// files, its #include and one entry in the variant below. Everything that depends on which
// integrator a scene uses dispatches here, on the variant: names, scene keys, settings text,
// checks and splatting (registry_settings.cpp, the scene library) and rendering (registry.cpp,
// the renderer).
#pragma once

#include <string>
#include <variant>
#include <vector>

#include "engine/integrators/ao.h"
#include "engine/integrators/bdpt.h"
#include "engine/integrators/direct.h"
#include "engine/integrators/ir.h"
#include "engine/integrators/light.h"
#include "engine/integrators/path/path.h"
#include "engine/integrators/ppm.h"
#include "engine/integrators/whitted.h"

namespace rf {

// In the order `known_integrators()` lists them.
using Integrator = std::variant<WhittedIntegrator, AoIntegrator, DirectIntegrator, PathIntegrator,
                                LightIntegrator, BdptIntegrator, IrIntegrator, PpmIntegrator>;

// The names accepted for "integrator.type" and --integrator.
const std::vector<std::string>& known_integrators();
// The integrator of that name with its default parameters; throws std::invalid_argument naming
// the known ones for any other name.
Integrator make_integrator(const std::string& name);
std::string integrator_name(const Integrator& integrator);
// Splatting integrators render whole-frame tasks and fill the splat plane (DESIGN.md).
struct IntegratorSettings;  // scene.h

bool integrator_splats(const Integrator& integrator);
bool integrator_needs_lights(const Integrator& integrator);

// Other renderers' integrator types (module.h, kPbrtTypes and kMitsubaTypes): the name of the
// integrator a type maps to, "" when none does; and the Mitsuba types one by one for a message
// ("path, volpath, volpathmis, prb (as path), ...").
std::string integrator_for_pbrt(const std::string& type);
std::string integrator_for_mitsuba(const std::string& type);
std::string mitsuba_integrator_types();
// The imported parameters of the integrator `settings` holds, through its module's mapping.
void map_pbrt_integrator(IntegratorSettings& settings, const ForeignParams& params);
void map_mitsuba_integrator(IntegratorSettings& settings, const ForeignParams& params);

// Reads render.integrator (`j`, at JSON path `path`): its type, then the keys that integrator
// accepts (its kKeys; any other key is an error): max_depth and rr_min_depth, then its own.
void parse_integrator(const JsonReader& r, const Json& j, const std::string& path,
                      IntegratorSettings& out);
// --integrator NAME: switches to that integrator with its default parameters (keeps them when it
// already is that one). Throws std::invalid_argument for an unknown name.
void set_integrator(IntegratorSettings& settings, const std::string& name);
// Imposes the max depth an integrator fixes (direct lighting: 1).
void apply_fixed_max_depth(IntegratorSettings& settings);

// Canonical text of the settings that change pixels, beside the scene digest in every buffer
// header: common settings, then the integrator's own (its settings_text()). Older .rfb files
// merge only while this text is unchanged.
std::string settings_text(const Scene& scene);
// Throws SceneError when the scene's integrator cannot render it (its check(); the coordinator
// runs it at submit, the Renderer at construction).
void check_renderable(const Scene& scene);
// Renders one task with the scene's integrator (ctx.scene): one dispatch per task.
SampleBuffer render_task(const RenderContext& ctx, const TaskKey& task, bool parallel);

}  // namespace rf
