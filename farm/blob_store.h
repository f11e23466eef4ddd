// Content-addressed storage of scene bundles (DESIGN.md "Coordinator": every asset stored and
// shipped by its SHA-256; no shared filesystem). The coordinator keeps blobs under its state
// directory; a worker keeps the same layout as its cache. A bundle is a list of (relative path,
// digest); materialize() lays it out as files so the engine's scene loader reads it unchanged.
#pragma once

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace rf {

struct BundleEntry {
  std::string path;    // relative, '/'-separated, no '..', not absolute
  std::string sha256;  // lower-case hex
  bool operator==(const BundleEntry&) const = default;
};

struct BlobError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Throws BlobError naming the path when a bundle path is absolute, contains '..' or is empty.
void check_bundle_path(const std::string& path);
bool is_sha256_hex(std::string_view s);

// The bundle of a scene file on disk: the scene file itself (its name) and every asset it names,
// each with its digest. Throws SceneError for a scene that does not load.
std::vector<BundleEntry> bundle_of_scene(const std::string& scene_path);

class BlobStore {
 public:
  explicit BlobStore(std::string dir);  // creates it

  bool has(const std::string& sha256) const;
  // Stores bytes under their digest; throws BlobError if `expected_sha256` is given and differs.
  std::string put(std::string_view bytes, const std::string& expected_sha256 = "");
  std::optional<std::string> get(const std::string& sha256) const;
  std::string path_of(const std::string& sha256) const;  // where the blob lives (or would)
  // Lays the bundle out under dir (hard links or copies of the blobs); throws BlobError naming
  // the first missing blob or bad path. Returns dir.
  std::string materialize(const std::vector<BundleEntry>& bundle, const std::string& dir) const;

  // Retention (the coordinator's blob collection, the worker's bounded cache): a blob's file
  // time is when it was last stored, asked for or used (touch), in Unix seconds.
  struct Entry {
    std::string sha256;
    uint64_t bytes = 0;
    double used_unix = 0;
  };
  std::vector<Entry> list() const;  // every stored blob (files that are not blobs left out)
  void touch(const std::string& sha256) const;   // used now (nothing if it is not stored)
  bool remove(const std::string& sha256) const;  // false if it was not stored

 private:
  std::string dir_;
};

}  // namespace rf
