// The shipped configuration files: config/default.yaml is exactly the effective default
// configuration (every key, with units), and every file in config/ loads without error.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "cli_support.hpp"
#include "test_support.hpp"

namespace planeslam::test {
namespace {

namespace fs = std::filesystem;

TEST(ConfigFiles, DefaultYamlListsTheEffectiveDefaults) {
  const fs::path dir = ScratchDir();
  const CliResult r = RunCli("run --print-config", dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string shipped = Slurp(fs::path(PLANESLAM_SOURCE_DIR) / "config/default.yaml");
  // The shipped file starts with a comment block, then the dump itself.
  const std::size_t start = shipped.find("\n\n");
  ASSERT_NE(start, std::string::npos);
  EXPECT_EQ(shipped.substr(start + 2), r.out)
      << "config/default.yaml is stale: regenerate it with "
         "'planeslam run --print-config' (see the file's header)";
}

TEST(ConfigFiles, EveryShippedFileLoads) {
  const fs::path dir = ScratchDir();
  int files = 0;
  for (const auto& entry : fs::directory_iterator(fs::path(PLANESLAM_SOURCE_DIR) / "config")) {
    if (entry.path().extension() != ".yaml") continue;
    ++files;
    const CliResult r = RunCli("run --print-config -c " + entry.path().string(), dir);
    EXPECT_EQ(r.exit_code, 0) << entry.path() << ": " << r.err;
  }
  EXPECT_GE(files, 5);
}

}  // namespace
}  // namespace planeslam::test
