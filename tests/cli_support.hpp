#pragma once
// Running the planeslam executable from tests: exit code, stdout, stderr.
#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace planeslam::test {

struct CliResult {
  int exit_code = -1;  ///< -1 when killed by a signal (a crash)
  int signal = 0;      ///< the signal when killed
  std::string out, err;
};

inline std::string Slurp(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// Runs `planeslam ARGS` (a shell-quoted argument string) with stdin from /dev/null, in `cwd`
/// when given; `dir` holds the captured stdout/stderr files.
inline CliResult RunCli(const std::string& args, const std::filesystem::path& dir,
                        const std::filesystem::path& cwd = {}) {
  const std::filesystem::path out = std::filesystem::absolute(dir / "cli_stdout.txt"),
                              err = std::filesystem::absolute(dir / "cli_stderr.txt");
  const std::string command = (cwd.empty() ? "" : "cd '" + cwd.string() + "' && ") +
                              std::string(PLANESLAM_BIN) + " " + args + " </dev/null >" +
                              out.string() + " 2>" + err.string();
  const int status = std::system(command.c_str());
  CliResult r;
  if (WIFEXITED(status)) {
    r.exit_code = WEXITSTATUS(status);
  } else if (WIFSIGNALED(status)) {
    r.signal = WTERMSIG(status);
  }
  r.out = Slurp(out);
  r.err = Slurp(err);
  return r;
}

/// Writes `text` to dir/name and returns the path.
inline std::string WriteText(const std::filesystem::path& dir, const std::string& name,
                             const std::string& text) {
  const std::string path = (dir / name).string();
  std::ofstream(path, std::ios::binary) << text;
  return path;
}

}  // namespace planeslam::test
