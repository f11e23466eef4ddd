// Content-addressed scene bundles: a scene and its assets round-trip through the blob store and
// load from the materialised directory with the same digest.
#include <gtest/gtest.h>

#include <filesystem>

#include "engine/digest.h"
#include "engine/scene.h"
#include "farm/blob_store.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

TEST(BlobStore, CornellBundleRoundTripsWithTheSameDigest) {
  std::string scene = test::source_dir() + "/scenes/cornell-box/scene.json";
  std::vector<BundleEntry> bundle = bundle_of_scene(scene);
  ASSERT_EQ(bundle.size(), 3u);  // scene.json and the two box meshes
  EXPECT_EQ(bundle[0].path, "scene.json");
  EXPECT_EQ(bundle[1].path, "meshes/short-box.obj");

  BlobStore store(test::make_temp_dir("blobs"));
  std::string dir = std::filesystem::path(scene).parent_path().string();
  for (const BundleEntry& e : bundle) {
    EXPECT_FALSE(store.has(e.sha256));
    EXPECT_EQ(store.put(read_file_bytes(dir + "/" + e.path), e.sha256), e.sha256);
    EXPECT_TRUE(store.has(e.sha256));
  }
  std::string out = store.materialize(bundle, test::make_temp_dir("bundle"));
  Scene a = load_scene(scene), b = load_scene(out + "/scene.json");
  EXPECT_EQ(a.digest, b.digest) << "the digest is a function of the bundle's contents alone";
}

TEST(BlobStore, RefusesBadDigestsPathsAndMissingBlobs) {
  BlobStore store(test::make_temp_dir("blobs-bad"));
  EXPECT_THROW(store.put("abc", std::string(64, '0')), BlobError);
  std::string d = store.put("abc");
  EXPECT_EQ(d, sha256_hex("abc"));
  EXPECT_THROW(check_bundle_path("../x.obj"), BlobError);
  EXPECT_THROW(check_bundle_path("/etc/passwd"), BlobError);
  EXPECT_THROW(check_bundle_path("a/../../b"), BlobError);
  EXPECT_NO_THROW(check_bundle_path("meshes/a.obj"));
  try {
    store.materialize({{"scene.json", d}, {"m.obj", std::string(64, 'a')}},
                      test::make_temp_dir("m"));
    FAIL();
  } catch (const BlobError& e) {
    EXPECT_NE(std::string(e.what()).find("of 'm.obj' is missing"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(store.has("not-a-digest"));
}

}  // namespace
}  // namespace rf
