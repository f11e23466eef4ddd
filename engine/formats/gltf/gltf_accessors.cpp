// Reading glTF accessors with every bound checked before a byte is read (the parser is fuzzed):
// accessor -> buffer view -> buffer, stride, element size, count, and sparse substitutions.
#include <algorithm>
#include <cmath>
#include <cstring>

#include "engine/formats/gltf/gltf_internal.h"

namespace rf::gltf {
namespace {

// A bufferView-less accessor is all zeros (plus sparse values); its count is not backed by
// bytes, so it is capped to keep a hostile file from allocating gigabytes.
constexpr size_t kMaxUnbackedCount = size_t(1) << 24;

int component_size(int type) {
  switch (type) {
    case TINYGLTF_COMPONENT_TYPE_BYTE:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
      return 1;
    case TINYGLTF_COMPONENT_TYPE_SHORT:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
      return 2;
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
    case TINYGLTF_COMPONENT_TYPE_FLOAT:
      return 4;
    default:
      return 0;  // INT (5124) and DOUBLE are not glTF 2.0 accessor types
  }
}

int type_components(int type) {
  switch (type) {
    case TINYGLTF_TYPE_SCALAR:
      return 1;
    case TINYGLTF_TYPE_VEC2:
      return 2;
    case TINYGLTF_TYPE_VEC3:
      return 3;
    case TINYGLTF_TYPE_VEC4:
      return 4;
    case TINYGLTF_TYPE_MAT2:
      return 4;
    case TINYGLTF_TYPE_MAT3:
      return 9;
    case TINYGLTF_TYPE_MAT4:
      return 16;
    default:
      return 0;
  }
}

std::string type_name(int components) {
  return components == 1 ? "SCALAR" : "VEC" + std::to_string(components);
}

// The bytes of a buffer view, checked against its buffer.
}  // namespace

ViewBytes view_bytes(const Context& c, int view, const std::string& where) {
  const auto& m = c.model;
  const std::string vp = ptr("/bufferViews", size_t(view));
  if (view < 0 || size_t(view) >= m.bufferViews.size())
    c.fail(where, "bufferView " + std::to_string(view) + " does not exist (the file has " +
                      std::to_string(m.bufferViews.size()) + ")");
  const tinygltf::BufferView& bv = m.bufferViews[size_t(view)];
  if (bv.buffer < 0 || size_t(bv.buffer) >= m.buffers.size())
    c.fail(ptr(vp, "buffer"), "buffer " + std::to_string(bv.buffer) +
                                  " does not exist (the file has " +
                                  std::to_string(m.buffers.size()) + ")");
  const auto& data = m.buffers[size_t(bv.buffer)].data;
  if (bv.byteOffset > data.size() || bv.byteLength > data.size() - bv.byteOffset)
    c.fail(vp, "bytes " + std::to_string(bv.byteOffset) + " + " + std::to_string(bv.byteLength) +
                   " lie outside buffer " + std::to_string(bv.buffer) + " (" +
                   std::to_string(data.size()) + " bytes)");
  return {data.data() + bv.byteOffset, bv.byteLength, bv.byteStride};
}

namespace {

float to_float(const unsigned char* p, int type, bool normalized) {
  switch (type) {
    case TINYGLTF_COMPONENT_TYPE_BYTE: {
      int8_t v;
      std::memcpy(&v, p, 1);
      return normalized ? std::max(float(v) / 127.0f, -1.0f) : float(v);
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
      return normalized ? float(*p) / 255.0f : float(*p);
    case TINYGLTF_COMPONENT_TYPE_SHORT: {
      int16_t v;
      std::memcpy(&v, p, 2);
      return normalized ? std::max(float(v) / 32767.0f, -1.0f) : float(v);
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
      uint16_t v;
      std::memcpy(&v, p, 2);
      return normalized ? float(v) / 65535.0f : float(v);
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
      uint32_t v;
      std::memcpy(&v, p, 4);
      return float(v);
    }
    default: {
      float v;
      std::memcpy(&v, p, 4);
      return v;
    }
  }
}

uint32_t to_index(const unsigned char* p, int type) {
  if (type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE) return *p;
  if (type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT) {
    uint16_t v;
    std::memcpy(&v, p, 2);
    return v;
  }
  uint32_t v;
  std::memcpy(&v, p, 4);
  return v;
}

bool is_index_type(int t) {
  return t == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ||
         t == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT || t == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
}

// The accessor's elements as raw bytes, element i at data + i * stride (sparse values applied
// into a private copy), after every check.
struct Elements {
  std::vector<unsigned char> storage;  // used when zero-filled or sparse
  const unsigned char* data = nullptr;
  size_t stride = 0, count = 0;
  int component_type = 0, components = 0;
  bool normalized = false;
};

Elements elements(const Context& c, int index, const std::string& where) {
  const auto& m = c.model;
  if (index < 0 || size_t(index) >= m.accessors.size())
    c.fail(where, "accessor " + std::to_string(index) + " does not exist (the file has " +
                      std::to_string(m.accessors.size()) + ")");
  const tinygltf::Accessor& a = m.accessors[size_t(index)];
  const std::string ap = ptr("/accessors", size_t(index));
  Elements e;
  e.component_type = a.componentType;
  e.components = type_components(a.type);
  e.normalized = a.normalized;
  e.count = a.count;
  const int csize = component_size(a.componentType);
  if (csize == 0)
    c.fail(ptr(ap, "componentType"), "unsupported component type " +
                                         std::to_string(a.componentType) +
                                         " (glTF 2.0: 5120, 5121, 5122, 5123, 5125, 5126)");
  if (e.components == 0) c.fail(ptr(ap, "type"), "unknown accessor type");
  const size_t elem = size_t(csize) * size_t(e.components);
  if (a.count == 0) c.fail(ptr(ap, "count"), "must be at least 1");
  if (a.bufferView < 0) {  // all zeros, then the sparse values
    if (a.count > kMaxUnbackedCount)
      c.fail(ptr(ap, "count"), std::to_string(a.count) +
                                   " elements without a bufferView (at most " +
                                   std::to_string(kMaxUnbackedCount) + ")");
    e.storage.assign(a.count * elem, 0);
    e.stride = elem;
  } else {
    ViewBytes v = view_bytes(c, a.bufferView, ptr(ap, "bufferView"));
    e.stride = v.stride ? v.stride : elem;
    if (v.stride && (v.stride < elem || v.stride > 252 || v.stride % 4 != 0))
      c.fail(ptr(ptr("/bufferViews", size_t(a.bufferView)), "byteStride"),
             "byteStride " + std::to_string(v.stride) + " must be a multiple of 4 in [" +
                 std::to_string(elem) + ", 252] for accessor " + std::to_string(index));
    // The last element ends at byteOffset + stride * (count - 1) + elem; count <= size keeps the
    // products far from overflow (stride <= 252).
    if (a.count > v.size || a.byteOffset > v.size ||
        e.stride * (a.count - 1) + elem > v.size - a.byteOffset)
      c.fail(ap, std::to_string(a.count) + " elements of " + std::to_string(elem) +
                     " bytes (stride " + std::to_string(e.stride) + ", byteOffset " +
                     std::to_string(a.byteOffset) + ") do not fit in bufferView " +
                     std::to_string(a.bufferView) + " (" + std::to_string(v.size) + " bytes)");
    e.data = v.data + a.byteOffset;
  }
  if (a.sparse.isSparse) {
    const std::string sp = ptr(ap, "sparse");
    const auto& s = a.sparse;
    if (s.count < 1 || size_t(s.count) > a.count)
      c.fail(ptr(sp, "count"),
             "must be in [1, " + std::to_string(a.count) + "], got " + std::to_string(s.count));
    if (e.storage.empty()) {  // copy the dense elements, then substitute
      e.storage.resize(a.count * elem);
      for (size_t i = 0; i < a.count; ++i)
        std::memcpy(&e.storage[i * elem], e.data + i * e.stride, elem);
      e.stride = elem;
    }
    const int isize =
        is_index_type(s.indices.componentType) ? component_size(s.indices.componentType) : 0;
    if (isize == 0) c.fail(ptr(ptr(sp, "indices"), "componentType"), "must be 5121, 5123 or 5125");
    const size_t n = size_t(s.count);
    ViewBytes iv = view_bytes(c, s.indices.bufferView, ptr(ptr(sp, "indices"), "bufferView"));
    ViewBytes vv = view_bytes(c, s.values.bufferView, ptr(ptr(sp, "values"), "bufferView"));
    if (s.indices.byteOffset < 0 || size_t(s.indices.byteOffset) > iv.size ||
        n * size_t(isize) > iv.size - size_t(s.indices.byteOffset))
      c.fail(ptr(sp, "indices"), std::to_string(n) + " indices do not fit in their bufferView");
    if (s.values.byteOffset < 0 || size_t(s.values.byteOffset) > vv.size || n > vv.size ||
        n * elem > vv.size - size_t(s.values.byteOffset))
      c.fail(ptr(sp, "values"), std::to_string(n) + " values do not fit in their bufferView");
    for (size_t k = 0; k < n; ++k) {
      uint32_t i = to_index(iv.data + s.indices.byteOffset + k * isize, s.indices.componentType);
      if (i >= a.count)
        c.fail(ptr(sp, "indices"), "index " + std::to_string(i) + " (entry " + std::to_string(k) +
                                       ") out of range (count " + std::to_string(a.count) + ")");
      std::memcpy(&e.storage[size_t(i) * elem], vv.data + s.values.byteOffset + k * elem, elem);
    }
  }
  if (!e.storage.empty()) e.data = e.storage.data();
  return e;
}

}  // namespace

std::vector<float> read_floats(const Context& c, int accessor, int components,
                               const std::string& where) {
  Elements e = elements(c, accessor, where);
  const std::string ap = ptr("/accessors", size_t(accessor));
  if (e.components != components)
    c.fail(ptr(ap, "type"), "expected " + type_name(components) + " for " + where);
  const int csize = component_size(e.component_type);
  std::vector<float> out(e.count * size_t(components));
  for (size_t i = 0; i < e.count; ++i)
    for (int k = 0; k < components; ++k) {
      float v = to_float(e.data + i * e.stride + size_t(k) * csize, e.component_type, e.normalized);
      if (!std::isfinite(v))
        c.fail(ap, "element " + std::to_string(i) + " is not finite (" + where + ")");
      out[i * components + k] = v;
    }
  return out;
}

std::vector<uint32_t> read_indices(const Context& c, int accessor, size_t vertex_count,
                                   const std::string& where) {
  Elements e = elements(c, accessor, where);
  const std::string ap = ptr("/accessors", size_t(accessor));
  if (e.components != 1) c.fail(ptr(ap, "type"), "indices must be SCALAR (" + where + ")");
  if (!is_index_type(e.component_type))
    c.fail(ptr(ap, "componentType"),
           "indices must be unsigned byte, short or int (5121, 5123, 5125)");
  std::vector<uint32_t> out(e.count);
  for (size_t i = 0; i < e.count; ++i) {
    out[i] = to_index(e.data + i * e.stride, e.component_type);
    if (out[i] >= vertex_count)
      c.fail(ap, "index " + std::to_string(out[i]) + " (element " + std::to_string(i) +
                     ") out of range: the primitive has " + std::to_string(vertex_count) +
                     " vertices");
  }
  return out;
}

}  // namespace rf::gltf
