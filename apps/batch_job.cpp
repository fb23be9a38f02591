#include "batch_job.hpp"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <thread>

#include "exit_codes.hpp"
#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/errors.hpp"

namespace planeslam::app {
namespace {

namespace fs = std::filesystem;
namespace ds = planeslam::datasets;

volatile sig_atomic_t g_child = 0;
volatile sig_atomic_t g_signals = 0;

/// SIGINT/SIGTERM/SIGHUP to the job: stop the run (its first SIGTERM writes the frames done, a
/// second one ends it at once); the job then records the attempt as interrupted.
void ForwardSignal(int) {
  g_signals = g_signals + 1;
  if (g_child > 0) ::kill(static_cast<pid_t>(g_child), SIGTERM);
}

std::string HostName() {
  char buffer[256] = {0};
  if (::gethostname(buffer, sizeof(buffer) - 1) != 0) return "host";
  std::string host = buffer;
  for (char& c : host) {
    if (c == '.' || c == '/') c = '_';
  }
  return host;
}

std::string ReadText(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// The last non-empty line of `path` (at most 300 characters), "" when none.
std::string LastLine(const fs::path& path) {
  std::istringstream in(ReadText(path));
  std::string line, last;
  while (std::getline(in, line)) {
    const auto end = line.find_last_not_of(" \t\r");
    if (end != std::string::npos) last = line.substr(0, end + 1);
  }
  // A progress bar redraws with carriage returns: keep what was drawn last.
  if (const auto cr = last.rfind('\r'); cr != std::string::npos) last = last.substr(cr + 1);
  return last.size() > 300 ? last.substr(0, 297) + "..." : last;
}

nlohmann::json ReadJson(const fs::path& path) {
  try {
    return nlohmann::json::parse(ReadText(path));
  } catch (const nlohmann::json::exception&) {
    return nullptr;
  }
}

struct ChildResult {
  int status = 0;
  bool timed_out = false;
  double time_limit_s = 0.0;
  double seconds = 0.0;
};

/// A descriptor that becomes readable when the child `pid` exits (Linux 5.3 and later), so that
/// the job notices the end of its run at once; -1 where the kernel has none (then it polls).
int OpenPidFd(pid_t pid) {
#ifdef SYS_pidfd_open
  return static_cast<int>(::syscall(SYS_pidfd_open, pid, 0));
#else
  (void)pid;
  return -1;
#endif
}

/// Waits at most `ms` milliseconds (< 0: without limit) for the run to exit or a signal.
void WaitForExit(int pidfd, int ms) {
  if (pidfd < 0) {
    std::this_thread::sleep_for(std::chrono::milliseconds(ms < 0 ? 20 : std::min(ms, 20)));
    return;
  }
  pollfd p{pidfd, POLLIN, 0};
  (void)::poll(&p, 1, ms);  // EINTR: a signal to forward, handled by the caller's loop
}

/// Runs `argv` with stdout and stderr in `dir`, until it exits or `time_limit_s` passes (then
/// SIGTERM, and SIGKILL 10 s later).
ChildResult RunChild(const std::vector<std::string>& argv, const fs::path& dir,
                     double time_limit_s) {
  const auto start = std::chrono::steady_clock::now();
  const std::string out = (dir / "stdout.log").string(), err = (dir / "stderr.log").string();
  std::vector<char*> c_argv;
  for (const auto& a : argv) c_argv.push_back(const_cast<char*>(a.c_str()));
  c_argv.push_back(nullptr);
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid < 0) throw IoError(dir.string(), std::string("cannot start the run: ") + std::strerror(errno));
  if (pid == 0) {
    // The run dies with its job (a killed job leaves no run behind writing into its folder).
    // Its own process group: a signal to the job's group reaches the run once, through the job.
    ::setpgid(0, 0);
    ::prctl(PR_SET_PDEATHSIG, SIGTERM);
    if (::getppid() != parent) ::_exit(kExitInterrupted);
    const int o = ::open(out.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    const int e = ::open(err.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (o < 0 || e < 0 || ::dup2(o, STDOUT_FILENO) < 0 || ::dup2(e, STDERR_FILENO) < 0) ::_exit(127);
    ::execv(c_argv[0], c_argv.data());
    const char msg[] = "planeslam batch: cannot execute the run\n";
    (void)!::write(STDERR_FILENO, msg, sizeof(msg) - 1);
    ::_exit(127);
  }
  g_child = pid;
  const int pidfd = OpenPidFd(pid);
  ChildResult result;
  result.time_limit_s = time_limit_s;
  bool term_sent = false;
  std::chrono::steady_clock::time_point term_time;
  for (;;) {
    const pid_t done = ::waitpid(pid, &result.status, WNOHANG);
    if (done == pid) break;
    if (done < 0 && errno != EINTR) {
      if (pidfd >= 0) ::close(pidfd);
      throw IoError(dir.string(), "lost the run's process");
    }
    const auto now = std::chrono::steady_clock::now();
    const double elapsed = std::chrono::duration<double>(now - start).count();
    if (time_limit_s > 0.0 && elapsed > time_limit_s && !term_sent) {
      result.timed_out = true;
      term_sent = true;
      term_time = now;
      ::kill(pid, SIGTERM);
    }
    if (term_sent && now - term_time > std::chrono::seconds(10)) ::kill(pid, SIGKILL);
    // Until the run exits, or the next deadline (time limit, then the SIGKILL after SIGTERM).
    int wait_ms = -1;
    if (term_sent) wait_ms = 100;
    else if (time_limit_s > 0.0) wait_ms = static_cast<int>((time_limit_s - elapsed) * 1000.0) + 1;
    WaitForExit(pidfd, std::min(wait_ms < 0 ? 1000 : wait_ms, 1000));
  }
  if (pidfd >= 0) ::close(pidfd);
  g_child = 0;
  result.seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

/// job.json of an attempt: its arguments and how it ended.
nlohmann::json AttemptRecord(const std::string& name, const std::vector<std::string>& command,
                             const ChildResult& r, const fs::path& dir) {
  nlohmann::json j;
  const auto slash = name.find('/');
  j["job"] = name;
  j["sequence"] = name.substr(0, slash);
  j["variant"] = name.substr(slash + 1);
  j["args"] = std::vector<std::string>(command.begin() + 2, command.end());
  j["host"] = HostName();
  j["seconds"] = r.seconds;
  std::string error = LastLine(dir / "stderr.log");
  if (WIFEXITED(r.status)) {
    const int code = WEXITSTATUS(r.status);
    j["exit_code"] = code;
    j["status"] = code == kExitSuccess                  ? "ok"
                  : code == kExitSkippedFrames          ? "skipped_frames"
                  : r.timed_out                         ? "timed_out"
                  : code == kExitInterrupted || g_signals ? "interrupted"
                                                        : "failed";
  } else {
    const int sig = WTERMSIG(r.status);
    j["exit_code"] = 128 + sig;
    j["signal"] = sig;
    j["status"] = r.timed_out ? "timed_out" : g_signals ? "interrupted" : "failed";
    error = std::string("killed by signal ") + std::to_string(sig) + " (" + ::strsignal(sig) +
            ")" + (error.empty() ? "" : "; last line: " + error);
  }
  if (j["status"] == "interrupted") error = "interrupted by a signal before it completed";
  if (r.timed_out) {
    std::ostringstream os;
    os << "time limit of " << r.time_limit_s << " s exceeded";
    error = os.str();
  }
  j["error"] = j["status"] == "ok" ? "" : error;
  return j;
}

bool SameArgs(const nlohmann::json& record, const std::vector<std::string>& args) {
  return record.is_object() && record.contains("args") && record["args"] == nlohmann::json(args);
}

/// Moves `from` to `to`, replacing an old `to`; returns false (and leaves `to`) when `to` holds
/// `args` already (a concurrent attempt of the same job finished first).
bool Publish(const fs::path& from, const fs::path& to, const std::string& meta,
             const std::vector<std::string>* args) {
  fs::create_directories(to.parent_path());
  if (::rename(from.c_str(), to.c_str()) == 0) return true;
  if (errno != ENOTEMPTY && errno != EEXIST) {
    throw IoError(to.string(), std::string("cannot move the job's outputs here: ") + std::strerror(errno));
  }
  if (args != nullptr && SameArgs(ReadJson(to / "job.json"), *args)) return false;
  // An outdated or failed folder: set it aside, put ours in place, then delete the old one.
  const fs::path trash = fs::path(meta) / "trash" /
                         (to.parent_path().filename().string() + "." + to.filename().string() +
                          "." + HostName() + "." + std::to_string(::getpid()));
  fs::create_directories(trash.parent_path());
  fs::rename(to, trash);
  fs::rename(from, to);
  fs::remove_all(trash);
  return true;
}

}  // namespace

std::string JobStatus::Error() const {
  if (!record.is_object()) return state == JobState::kMissing ? "not run" : "";
  std::string e = record.value("status", std::string("failed"));
  if (record.contains("exit_code")) e += " (exit " + std::to_string(record["exit_code"].get<int>()) + ")";
  const std::string line = record.value("error", std::string());
  return line.empty() ? e : e + ": " + line;
}

std::string BatchMetaDir(const std::string& batch_dir) {
  return (fs::path(batch_dir) / ".batch").string();
}

JobStatus ReadJobStatus(const std::string& batch_dir, const BatchJob& job) {
  JobStatus s;
  const fs::path done = fs::path(batch_dir) / job.sequence / job.variant;
  if (fs::is_directory(done)) {
    s.record = ReadJson(done / "job.json");
    s.state = SameArgs(s.record, job.run_args) ? JobState::kComplete : JobState::kOutdated;
    return s;
  }
  const fs::path failed = fs::path(BatchMetaDir(batch_dir)) / "failed" / job.sequence / job.variant;
  if (fs::is_directory(failed)) {
    s.record = ReadJson(failed / "job.json");
    s.state = JobState::kFailed;
  }
  return s;
}

void RemoveStaleAttempts(const std::string& batch_dir, const std::vector<BatchJob>& jobs) {
  const std::string host = HostName();
  std::vector<fs::path> folders = {fs::path(BatchMetaDir(batch_dir)) / "trash"};
  for (const BatchJob& job : jobs) folders.push_back(fs::path(batch_dir) / job.sequence);
  for (const fs::path& folder : folders) {
    std::error_code ec;
    if (!fs::is_directory(folder, ec)) continue;
    for (const auto& entry : fs::directory_iterator(folder, ec)) {
      // Names end in ".<host>.<pid>"; only attempts of this host can be checked for life.
      const std::string name = entry.path().filename().string();
      const auto dot = name.rfind('.');
      if (dot == std::string::npos || dot < host.size() + 1) continue;
      if (name.compare(dot - host.size() - 1, host.size() + 1, "." + host) != 0) continue;
      if (folder.filename() != "trash" && (name[0] != '.' || name.find(".tmp.") == std::string::npos)) continue;
      const long pid = std::strtol(name.c_str() + dot + 1, nullptr, 10);
      if (pid > 0 && ::kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH) {
        fs::remove_all(entry.path(), ec);
      }
    }
  }
}

int RunBatchJob(const std::string& batch_dir, const std::string& name, double time_limit_s,
                const std::vector<std::string>& command) {
  const auto slash = name.find('/');
  if (slash == std::string::npos || command.size() < 2) {
    throw ConfigError("batch job: expected <sequence>/<variant> -- planeslam run ARGS");
  }
  struct sigaction action {};
  action.sa_handler = ForwardSignal;
  sigemptyset(&action.sa_mask);
  for (int sig : {SIGINT, SIGTERM, SIGHUP}) ::sigaction(sig, &action, nullptr);
  const fs::path final_dir = fs::path(batch_dir) / name;
  const std::vector<std::string> args(command.begin() + 2, command.end());
  if (fs::is_directory(final_dir) && SameArgs(ReadJson(final_dir / "job.json"), args)) {
    std::cout << name << ": already complete\n";
    return kExitSuccess;
  }
  const fs::path tmp = final_dir.parent_path() / ("." + final_dir.filename().string() + ".tmp." +
                                                  HostName() + "." + std::to_string(::getpid()));
  fs::create_directories(tmp);

  std::vector<std::string> argv = command;
  argv.insert(argv.end(), {"--out", tmp.string()});
  // The cores this job may use: Slurm's allocation, or the local batch's share of the machine.
  // Not part of the recorded arguments: the thread count never changes a run's outputs.
  for (const char* var : {"SLURM_CPUS_PER_TASK", "PLANESLAM_BATCH_THREADS"}) {
    const char* value = std::getenv(var);
    if (value != nullptr && std::atoi(value) > 0) {
      argv.insert(argv.end(), {"--threads", std::to_string(std::atoi(value))});
      break;
    }
  }
  if (g_signals > 0) {  // interrupted before the run started: nothing to record
    fs::remove_all(tmp);
    return kExitInterrupted;
  }
  const ChildResult result = RunChild(argv, tmp, time_limit_s);
  const nlohmann::json record = AttemptRecord(name, command, result, tmp);
  ds::WriteFileAtomic((tmp / "job.json").string(), record.dump(2) + "\n");
  const std::string status = record["status"];
  const std::string meta = BatchMetaDir(batch_dir);
  const fs::path failed_dir = fs::path(meta) / "failed" / name;
  char seconds[32];
  std::snprintf(seconds, sizeof(seconds), "%.1f s", result.seconds);
  if (status == "ok" || status == "skipped_frames") {
    if (!Publish(tmp, final_dir, meta, &args)) {
      fs::remove_all(tmp);
      std::cout << name << ": already complete (a concurrent attempt finished first)\n";
      return kExitSuccess;
    }
    fs::remove_all(failed_dir);
    std::cout << name << ": " << status << ", " << seconds << "\n";
    return kExitSuccess;
  }
  Publish(tmp, failed_dir, meta, nullptr);
  JobStatus s;
  s.state = JobState::kFailed;
  s.record = record;
  std::cout << name << ": FAILED " << s.Error() << "\n";
  const int code = record["exit_code"].get<int>();
  return code == 0 ? kExitError : code;
}

}  // namespace planeslam::app
