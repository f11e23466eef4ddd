// The body of the layer link checks (tests/CMakeLists.txt, docs/design.md "Libraries"): each
// check links every object of one library (whole archive) with only the libraries that library
// declares. A call from the scene library into the renderer, from the client into the engine or
// from the coordinator into gRPC is then an undefined symbol when the check links. Running it
// shows the library's static initialisers run on their own.
#include <cstdio>

int main() {
  std::printf("%s links on its own\n", RAYFARM_LAYER);
  return 0;
}
