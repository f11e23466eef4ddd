#include "farm/blob_store.h"

#include <fcntl.h>
#include <sys/stat.h>

#include <filesystem>

#include "engine/digest.h"
#include "engine/scene.h"
#include "farm/job.h"

namespace rf {

namespace fs = std::filesystem;

bool is_sha256_hex(std::string_view s) {
  if (s.size() != 64) return false;
  for (char c : s)
    if (!((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'))) return false;
  return true;
}

void check_bundle_path(const std::string& path) {
  if (path.empty()) throw BlobError("bundle path is empty");
  if (std::string why = text_problem(path); !why.empty())
    throw BlobError("bundle path '" + printable(path) + "': " + why);
  if (path.front() == '/' || fs::path(path).is_absolute())
    throw BlobError("bundle path '" + path + "' is absolute");
  if (path.find('\\') != std::string::npos)
    throw BlobError("bundle path '" + path + "' uses '\\'; use '/'");
  for (const fs::path& part : fs::path(path))
    if (part == "..") throw BlobError("bundle path '" + path + "' contains '..'");
}

std::vector<BundleEntry> bundle_of_scene(const std::string& scene_path) {
  Scene s = load_scene(scene_path);
  fs::path dir = fs::path(scene_path).parent_path();
  std::vector<BundleEntry> out;
  std::string name = fs::path(scene_path).filename().string();
  out.push_back({name, sha256_hex(read_file_bytes(scene_path))});
  for (const std::string& a : s.assets)
    out.push_back({a, sha256_hex(read_file_bytes((dir / a).string()))});
  return out;
}

BlobStore::BlobStore(std::string dir) : dir_(std::move(dir)) {
  std::error_code ec;
  fs::create_directories(dir_, ec);
  if (ec) throw BlobError(dir_ + ": cannot create the blob store: " + ec.message());
}

std::string BlobStore::path_of(const std::string& sha256) const {
  return dir_ + "/" + sha256.substr(0, 2) + "/" + sha256;
}

bool BlobStore::has(const std::string& sha256) const {
  return is_sha256_hex(sha256) && fs::exists(path_of(sha256));
}

std::string BlobStore::put(std::string_view bytes, const std::string& expected_sha256) {
  std::string digest = sha256_hex(bytes);
  if (!expected_sha256.empty() && digest != expected_sha256)
    throw BlobError("blob digest " + digest + " does not match the announced " + expected_sha256);
  if (!has(digest)) {
    fs::create_directories(fs::path(path_of(digest)).parent_path());
    write_file_atomic(path_of(digest), bytes);
  } else {
    touch(digest);  // stored again: its grace period starts now
  }
  return digest;
}

std::optional<std::string> BlobStore::get(const std::string& sha256) const {
  if (!has(sha256)) return std::nullopt;
  return read_file_bytes(path_of(sha256));
}

std::vector<BlobStore::Entry> BlobStore::list() const {
  std::vector<Entry> out;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(dir_, ec); !ec && it != fs::end(it);
       it.increment(ec)) {
    const std::string name = it->path().filename().string();
    std::error_code e;
    if (!is_sha256_hex(name) || !it->is_regular_file(e)) continue;
    struct stat st {};
    if (::stat(it->path().c_str(), &st) != 0) continue;
    out.push_back(
        {name, uint64_t(st.st_size), double(st.st_mtim.tv_sec) + st.st_mtim.tv_nsec * 1e-9});
  }
  return out;
}

void BlobStore::touch(const std::string& sha256) const {
  if (!is_sha256_hex(sha256)) return;
  ::utimensat(AT_FDCWD, path_of(sha256).c_str(), nullptr, 0);  // both times: now
}

bool BlobStore::remove(const std::string& sha256) const {
  if (!is_sha256_hex(sha256)) return false;
  std::error_code ec;
  return fs::remove(path_of(sha256), ec);
}

std::string BlobStore::materialize(const std::vector<BundleEntry>& bundle,
                                   const std::string& dir) const {
  for (const BundleEntry& e : bundle) {
    check_bundle_path(e.path);
    if (!has(e.sha256)) throw BlobError("blob " + e.sha256 + " of '" + e.path + "' is missing");
  }
  for (const BundleEntry& e : bundle) {
    fs::path target = fs::path(dir) / e.path;
    fs::create_directories(target.parent_path());
    std::error_code ec;
    fs::remove(target, ec);
    fs::create_hard_link(path_of(e.sha256), target, ec);
    if (ec) fs::copy_file(path_of(e.sha256), target, fs::copy_options::overwrite_existing);
  }
  return dir;
}

}  // namespace rf
