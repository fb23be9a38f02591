#include <gtest/gtest.h>

#include <string>

#include "config.hpp"

namespace planeslam::app {
namespace {

struct ToyConfig {
  double threshold = 0.5;  ///< [m]
  int size = 3;            ///< [cells]
  bool enabled = true;
  std::string mode = "grid";
};

void VisitToy(FieldVisitor& v, ToyConfig& c) {
  v.Field("threshold", c.threshold, "[m]", 0.0, 10.0);
  v.Field("size", c.size, "[cells]", 1, 64);
  v.Field("enabled", c.enabled, "");
  v.Field("mode", c.mode, "", {"grid", "point"});
}

std::vector<std::string> ValidateToy(const ToyConfig& c) {
  if (c.mode == "point" && c.size > 8) return {"size must be <= 8 for mode point"};
  return {};
}

PLANESLAM_REGISTER_CONFIG_SECTION(ToyConfig, "zz_test_toy", "test-only section", &VisitToy,
                                  &ValidateToy);

TEST(Config, DefaultsAndOverrides) {
  Config config;
  EXPECT_DOUBLE_EQ(config.Get<ToyConfig>("zz_test_toy").threshold, 0.5);
  config.LoadString("zz_test_toy:\n  threshold: 1.25\n  mode: point\n", "t.yaml");
  EXPECT_DOUBLE_EQ(config.Get<ToyConfig>("zz_test_toy").threshold, 1.25);
  EXPECT_EQ(config.Get<ToyConfig>("zz_test_toy").mode, "point");
  config.Set("zz_test_toy.size=5");
  EXPECT_EQ(config.Get<ToyConfig>("zz_test_toy").size, 5);
}

std::string LoadError(const std::string& yaml) {
  Config config;
  try {
    config.LoadString(yaml, "bad.yaml");
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(Config, ErrorsNameFileKeyAndReason) {
  EXPECT_EQ(LoadError("zz_test_toy:\n  treshold: 1\n"),
            "bad.yaml: key 'zz_test_toy.treshold': unknown key");
  EXPECT_EQ(LoadError("nosuch:\n  a: 1\n"), "bad.yaml: key 'nosuch': unknown section");
  EXPECT_EQ(LoadError("zz_test_toy:\n  threshold: abc\n"),
            "bad.yaml: key 'zz_test_toy.threshold': expected a number, got 'abc'");
  EXPECT_EQ(LoadError("zz_test_toy:\n  threshold: .nan\n"),
            "bad.yaml: key 'zz_test_toy.threshold': expected a number, got '.nan'");
  EXPECT_EQ(LoadError("zz_test_toy:\n  size: 100\n"),
            "bad.yaml: key 'zz_test_toy.size': 100 is out of range [1, 64]");
  EXPECT_EQ(LoadError("zz_test_toy:\n  size: 2.5\n"),
            "bad.yaml: key 'zz_test_toy.size': expected an integer, got '2.5'");
  EXPECT_EQ(LoadError("zz_test_toy:\n  enabled: maybe\n"),
            "bad.yaml: key 'zz_test_toy.enabled': expected true or false, got 'maybe'");
  EXPECT_EQ(LoadError("zz_test_toy:\n  mode: other\n"),
            "bad.yaml: key 'zz_test_toy.mode': 'other' is not one of: grid, point");
  EXPECT_EQ(LoadError("zz_test_toy:\n  mode: point\n  size: 9\n"),
            "bad.yaml: section 'zz_test_toy': size must be <= 8 for mode point");
  EXPECT_NE(LoadError("zz_test_toy: [1, 2\n").find("bad.yaml:"), std::string::npos);
}

// Found by fuzz_config: YAML allows a mapping or a list as a key ("? ..."), and converting such a
// key to a name threw yaml-cpp's own exception past the config loader.
TEST(Config, KeysThatAreListsOrMappingsAreRefused) {
  EXPECT_EQ(LoadError("output:\n? rkey:\n  d "),
            "bad.yaml:2: a key must be a plain name, not a list or mapping");
  EXPECT_EQ(LoadError("zz_test_toy:\n  ? [a, b]\n  : 1\n"),
            "bad.yaml: section 'zz_test_toy':2: a key must be a plain name, not a list or mapping");
}

TEST(Config, FailedLoadLeavesValuesUnchanged) {
  Config config;
  EXPECT_THROW(config.LoadString("zz_test_toy:\n  threshold: 2\n  size: 0\n", "x"), ConfigError);
  EXPECT_DOUBLE_EQ(config.Get<ToyConfig>("zz_test_toy").threshold, 0.5);
}

TEST(Config, DumpRoundTrips) {
  Config a;
  a.LoadString("zz_test_toy:\n  threshold: 0.1\n  mode: point\n", "t");
  Config b;
  b.LoadString(a.ToYaml(true), "dump");
  EXPECT_DOUBLE_EQ(b.Get<ToyConfig>("zz_test_toy").threshold, 0.1);
  EXPECT_EQ(b.Get<ToyConfig>("zz_test_toy").mode, "point");
  EXPECT_EQ(a.ToYaml(true), b.ToYaml(true));
}

}  // namespace
}  // namespace planeslam::app
