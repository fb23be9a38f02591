// The shipped configuration files: config/reference.yaml is exactly the effective default
// configuration (every key, with units), config/basic.yaml is a short subset of it at the
// defaults, and every file in config/ loads without error.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <filesystem>
#include <sstream>
#include <string>

#include "cli_support.hpp"
#include "config.hpp"
#include "test_support.hpp"

namespace planeslam::test {
namespace {

namespace fs = std::filesystem;

fs::path ConfigDir() { return fs::path(PLANESLAM_SOURCE_DIR) / "config"; }

TEST(ConfigFiles, ReferenceYamlListsTheEffectiveDefaults) {
  const fs::path dir = ScratchDir();
  const CliResult r = RunCli("run --print-config", dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string shipped = Slurp(ConfigDir() / "reference.yaml");
  // The shipped file starts with a comment block, then the dump itself.
  const std::size_t start = shipped.find("\n\n");
  ASSERT_NE(start, std::string::npos);
  EXPECT_EQ(shipped.substr(start + 2), r.out)
      << "config/reference.yaml is stale: regenerate it with "
         "'planeslam run --print-config' (see the file's header)";
}

TEST(ConfigFiles, BasicYamlIsAShortSubsetOfTheReferenceAtTheDefaults) {
  const fs::path basic_path = ConfigDir() / "basic.yaml";
  app::Config basic;
  ASSERT_NO_THROW(basic.LoadFile(basic_path.string()));

  const YAML::Node file = YAML::LoadFile(basic_path.string());
  const YAML::Node reference = YAML::LoadFile((ConfigDir() / "reference.yaml").string());
  ASSERT_TRUE(file.IsMap());
  int keys = 0;
  for (const auto& section : file) {
    const std::string name = section.first.as<std::string>();
    ASSERT_TRUE(section.second.IsMap()) << name;
    for (const auto& key : section.second) {
      ++keys;
      const std::string field = key.first.as<std::string>();
      EXPECT_TRUE(reference[name] && reference[name][field])
          << name << "." << field << " is not in config/reference.yaml";
    }
  }
  EXPECT_GT(keys, 0);
  EXPECT_LE(keys, 20) << "config/basic.yaml holds only the keys a user tunes";

  // Every key line carries its one-line comment.
  std::istringstream lines(Slurp(basic_path));
  for (std::string line; std::getline(lines, line);) {
    if (line.rfind("  ", 0) == 0) {
      EXPECT_NE(line.find(" # "), std::string::npos) << line;
    }
  }

  // Loading it changes nothing.
  EXPECT_EQ(basic.ToYaml(false), app::Config().ToYaml(false));
}

TEST(ConfigFiles, EveryShippedFileLoads) {
  const fs::path dir = ScratchDir();
  int files = 0;
  for (const auto& entry : fs::directory_iterator(ConfigDir())) {
    if (entry.path().extension() != ".yaml") continue;
    ++files;
    const CliResult r = RunCli("run --print-config -c " + entry.path().string(), dir);
    EXPECT_EQ(r.exit_code, 0) << entry.path() << ": " << r.err;
  }
  EXPECT_GE(files, 5);
}

}  // namespace
}  // namespace planeslam::test
