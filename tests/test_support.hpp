#pragma once
// Shared helpers for the planeslam test suites: where the real data is, scratch folders.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <functional>
#include <string>

#include "planeslam/datasets/errors.hpp"

namespace planeslam::test {

/// Folder of the shared real data: $PLANESLAM_DATA_DIR, else ../shared/data beside the checkout.
inline std::filesystem::path DataDir() {
  if (const char* env = std::getenv("PLANESLAM_DATA_DIR"); env && *env) return env;
  return PLANESLAM_DEFAULT_DATA_DIR;
}

/// True when the shared data folder exists (tests that need it skip otherwise).
inline bool HaveData() { return std::filesystem::is_directory(DataDir()); }

/// A fresh empty scratch folder unique to the running test.
inline std::filesystem::path ScratchDir() {
  const ::testing::TestInfo* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::filesystem::path root = std::filesystem::temp_directory_path() / "planeslam_tests";
  if (const char* env = std::getenv("PLANESLAM_TEST_TMP"); env && *env) root = env;
  std::filesystem::path dir =
      root / (std::string(info->test_suite_name()) + "." + info->name());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

/// The message of the IoError `f` throws, or "" when it throws none.
inline std::string ErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const IoError& e) {
    return e.what();
  }
  return "";
}

}  // namespace planeslam::test

/// Skips the current test with a clear message when the shared data folder is absent.
#define PLANESLAM_REQUIRE_DATA()                                                        \
  do {                                                                                  \
    if (!::planeslam::test::HaveData())                                                 \
      GTEST_SKIP() << "shared data not found at " << ::planeslam::test::DataDir()       \
                   << " (set PLANESLAM_DATA_DIR to run this test)";                     \
  } while (0)
