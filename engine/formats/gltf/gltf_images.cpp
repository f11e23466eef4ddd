// Images a glTF file embeds (in a .glb's binary chunk, a buffer view of a .bin, or a data: URI)
// are written to a content-addressed cache, <cache>/<sha256>.<png|jpg>, so OpenImageIO reads
// files. The scene digest already covers those bytes (the main file, or the registered .bin), a
// farm worker re-imports the same bundle and extracts the same names, and a file is written
// atomically (temporary file + rename), so concurrent imports never see half an image.
#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "engine/digest.h"
#include "engine/formats/gltf/gltf_internal.h"

namespace rf::gltf {
namespace {

namespace fs = std::filesystem;

// The extension OpenImageIO needs, by the file's magic bytes (the mimeType may lie or be absent).
std::string image_extension(std::string_view b) {
  if (b.size() >= 8 && b.substr(0, 8) == std::string_view("\x89PNG\r\n\x1a\n", 8)) return "png";
  if (b.size() >= 3 && b.substr(0, 3) == std::string_view("\xff\xd8\xff", 3)) return "jpg";
  return "";
}

bool same_bytes(const fs::path& p, std::string_view bytes) {
  std::error_code ec;
  if (fs::file_size(p, ec) != bytes.size() || ec) return false;
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str() == bytes;
}

std::string extract(const Context& c, std::string_view bytes, const std::string& where) {
  std::string ext = image_extension(bytes);
  if (ext.empty())
    c.fail(where, "the embedded image is neither PNG nor JPEG (the formats glTF 2.0 allows)");
  fs::path dir = image_cache_dir();
  fs::path out = dir / (sha256_hex(bytes) + "." + ext);
  if (same_bytes(out, bytes)) return out.string();
  std::error_code ec;
  fs::create_directories(dir, ec);
  static std::atomic<unsigned> serial{0};
  fs::path tmp = dir / ("." + out.filename().string() + ".tmp." + std::to_string(::getpid()) + "." +
                        std::to_string(serial++));
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    f.write(bytes.data(), std::streamsize(bytes.size()));
    f.close();
    if (!f) {
      fs::remove(tmp, ec);
      c.fail(where, "cannot write the embedded image to " + tmp.string() +
                        " (set XDG_CACHE_HOME to a writable directory)");
    }
  }
  fs::rename(tmp, out, ec);
  if (ec) {
    fs::remove(tmp, ec);
    c.fail(where, "cannot write the embedded image to " + out.string() + ": " + ec.message());
  }
  return out.string();
}

int hex_digit(char h) {
  if (h >= '0' && h <= '9') return h - '0';
  if (h >= 'a' && h <= 'f') return h - 'a' + 10;
  if (h >= 'A' && h <= 'F') return h - 'A' + 10;
  return -1;
}

}  // namespace

std::string percent_decode(const std::string& uri) {
  std::string out;
  for (size_t i = 0; i < uri.size(); ++i) {
    int hi = -1, lo = -1;
    if (uri[i] == '%' && i + 2 < uri.size() && (hi = hex_digit(uri[i + 1])) >= 0 &&
        (lo = hex_digit(uri[i + 2])) >= 0) {
      out.push_back(char(hi * 16 + lo));
      i += 2;
    } else {
      out.push_back(uri[i]);
    }
  }
  return out;
}

std::string image_cache_dir() {
  const char* xdg = std::getenv("XDG_CACHE_HOME");
  const char* home = std::getenv("HOME");
  if (xdg && *xdg == '/') return std::string(xdg) + "/rayfarm/gltf-images";
  if (home && *home) return std::string(home) + "/.cache/rayfarm/gltf-images";
  return (fs::temp_directory_path() / "rayfarm-gltf-images").string();
}

std::string image_file(Context& c, int index, const std::string& where) {
  if (index < 0 || size_t(index) >= c.model.images.size())
    c.fail(where, "image " + std::to_string(index) + " does not exist (the file has " +
                      std::to_string(c.model.images.size()) + ")");
  if (auto it = c.image_paths.find(index); it != c.image_paths.end()) return it->second;
  const tinygltf::Image& img = c.model.images[size_t(index)];
  const std::string ip = ptr("/images", size_t(index));
  std::string path;
  if (img.bufferView >= 0) {
    ViewBytes v = view_bytes(c, img.bufferView, ptr(ip, "bufferView"));
    path = extract(c, std::string_view(reinterpret_cast<const char*>(v.data), v.size), ip);
  } else if (auto d = c.data_uri_images.find(index); d != c.data_uri_images.end()) {
    path = extract(c, d->second, ptr(ip, "uri"));
  } else if (!img.uri.empty()) {
    std::string name = c.files->add(percent_decode(img.uri), ptr(ip, "uri"), "image");
    path = c.files->path_of(name);
  } else {
    c.fail(ip, "the image has neither a readable uri nor a bufferView");
  }
  c.image_paths[index] = path;
  return path;
}

}  // namespace rf::gltf
