#include "batch_dispatch.hpp"

#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <sstream>
#include <string>
#include <thread>

#include "batch_job.hpp"
#include "exit_codes.hpp"
#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/errors.hpp"

namespace planeslam::app {
namespace {

namespace fs = std::filesystem;
namespace ds = planeslam::datasets;

volatile sig_atomic_t g_engine = 0;
volatile sig_atomic_t g_interrupted = 0;

void ForwardToEngine(int) {
  g_interrupted = 1;
  if (g_engine > 0) ::kill(static_cast<pid_t>(g_engine), SIGINT);
}

/// Starts `argv` (searched on PATH), its stdout into `stdout_fd` when >= 0; the child gets SIGTERM
/// when this process dies.
pid_t Spawn(const std::vector<std::string>& argv, int stdout_fd) {
  std::vector<char*> c_argv;
  for (const auto& a : argv) c_argv.push_back(const_cast<char*>(a.c_str()));
  c_argv.push_back(nullptr);
  std::cout.flush();
  std::fflush(nullptr);
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid < 0) throw IoError(argv[0], std::string("cannot start: ") + std::strerror(errno));
  if (pid == 0) {
    ::prctl(PR_SET_PDEATHSIG, SIGTERM);
    if (::getppid() != parent) ::_exit(kExitInterrupted);
    if (stdout_fd >= 0) ::dup2(stdout_fd, STDOUT_FILENO);
    ::execvp(c_argv[0], c_argv.data());
    ::_exit(127);
  }
  return pid;
}

int WaitExitCode(pid_t pid) {
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) return kExitInternalError;
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

/// "0-3,5,7-8" of sorted indices.
std::string ArraySpec(const std::vector<std::size_t>& indices) {
  std::ostringstream os;
  for (std::size_t i = 0; i < indices.size();) {
    std::size_t j = i;
    while (j + 1 < indices.size() && indices[j + 1] == indices[j] + 1) ++j;
    os << (i == 0 ? "" : ",") << indices[i];
    if (j > i) os << "-" << indices[j];
    i = j + 1;
  }
  return os.str();
}

}  // namespace

std::string FindOnPath(const std::string& name) {
  const char* path = std::getenv("PATH");
  std::stringstream ss(path != nullptr ? path : "/usr/bin:/bin");
  std::string dir;
  while (std::getline(ss, dir, ':')) {
    const fs::path candidate = fs::path(dir.empty() ? "." : dir) / name;
    if (::access(candidate.c_str(), X_OK) == 0) return candidate.string();
  }
  return "";
}

std::string JobCommandLine(const std::string& binary, const std::string& batch_dir,
                           const BatchJob& job, double time_limit_s) {
  // The light job wrapper built beside planeslam, else planeslam's own `batch job`.
  const std::string runner = (fs::path(binary).parent_path() / "planeslam-batch-job").string();
  std::vector<std::string> line = {binary, "batch", "job", batch_dir, job.name};
  if (::access(runner.c_str(), X_OK) == 0) line = {runner, batch_dir, job.name};
  if (time_limit_s > 0.0) {
    std::ostringstream os;
    os << time_limit_s;
    line.insert(line.end(), {"--time-limit", os.str()});
  }
  line.insert(line.end(), {"--", binary, "run"});
  line.insert(line.end(), job.run_args.begin(), job.run_args.end());
  return ShellJoin(line);
}

std::string RunCommandLine(const std::string& binary, const std::string& batch_dir,
                           const BatchJob& job) {
  std::vector<std::string> line = {binary, "run"};
  line.insert(line.end(), job.run_args.begin(), job.run_args.end());
  line.insert(line.end(), {"--out", (fs::path(batch_dir) / job.name).string()});
  return ShellJoin(line);
}

int RunWithParallel(const BatchPlan& plan, const std::string& binary, const std::string& batch_dir,
                    const std::vector<std::size_t>& pending, int jobs) {
  if (FindOnPath("parallel").empty()) {
    throw IoError("parallel", "GNU parallel is not on PATH (Debian: apt-get install parallel)");
  }
  const std::string meta = BatchMetaDir(batch_dir);
  const std::string commands = meta + "/commands.txt";
  std::string lines;
  for (std::size_t i : pending) {
    lines += JobCommandLine(binary, batch_dir, plan.jobs[i], plan.time_limit_s) + "\n";
  }
  ds::WriteFileAtomic(commands, lines);
  // Each input line is one command. On an interruption parallel passes SIGINT on to the jobs and
  // gives them time to record their attempt before it escalates.
  const std::vector<std::string> argv = {
      "parallel",   "--will-cite",  "--line-buffer",
      "--jobs",     jobs > 0 ? std::to_string(jobs) : std::string("100%"),
      "--termseq",  "INT,5000,TERM,5000,KILL,25",
      "--joblog",   meta + "/parallel.joblog",
      "--arg-file", commands};
  ::setenv("PARALLEL_SHELL", "/bin/sh", 1);
  // Jobs running side by side share the cores instead of each starting one thread per core.
  const int cores = std::max(1u, std::thread::hardware_concurrency());
  const int slots = jobs > 0 ? jobs : cores;
  ::setenv("PLANESLAM_BATCH_THREADS", std::to_string(std::max(1, cores / slots)).c_str(), 1);
  struct sigaction action {}, old_int{}, old_term{};
  action.sa_handler = ForwardToEngine;
  sigemptyset(&action.sa_mask);
  ::sigaction(SIGINT, &action, &old_int);
  ::sigaction(SIGTERM, &action, &old_term);
  g_interrupted = 0;
  const pid_t pid = Spawn(argv, -1);
  g_engine = pid;
  const int code = WaitExitCode(pid);
  g_engine = 0;
  ::sigaction(SIGINT, &old_int, nullptr);
  ::sigaction(SIGTERM, &old_term, nullptr);
  return g_interrupted ? kExitInterrupted : code;
}

std::string SlurmScript(const BatchPlan& plan, const std::string& binary,
                        const std::string& batch_dir, const std::vector<std::size_t>& pending,
                        const SlurmOptions& slurm, double time_limit_s) {
  std::ostringstream s;
  s << "#!/bin/bash\n"
    << "# planeslam batch: " << pending.size() << " of the " << plan.jobs.size() << " jobs of "
    << plan.manifest << "\n# as a Slurm job array; array task i runs job i below and writes "
    << batch_dir << "/<sequence>/<variant>/.\n";
  s << "#SBATCH --job-name=planeslam-batch\n";
  s << "#SBATCH --array=" << ArraySpec(pending);
  if (slurm.max_parallel > 0) s << "%" << slurm.max_parallel;
  s << "\n#SBATCH --ntasks=1\n";
  s << "#SBATCH --cpus-per-task=" << std::max(1, slurm.cpus_per_task) << "\n";
  if (time_limit_s > 0.0) s << "#SBATCH --time=" << FormatSlurmTime(time_limit_s) << "\n";
  if (!slurm.mem.empty()) s << "#SBATCH --mem=" << slurm.mem << "\n";
  if (!slurm.partition.empty()) s << "#SBATCH --partition=" << slurm.partition << "\n";
  if (!slurm.account.empty()) s << "#SBATCH --account=" << slurm.account << "\n";
  if (!slurm.qos.empty()) s << "#SBATCH --qos=" << slurm.qos << "\n";
  for (const auto& e : slurm.extra) s << "#SBATCH " << e << "\n";
  // Slurm's own log of each task; the run's stdout and stderr go to the job's folder.
  s << "#SBATCH --output=" << BatchMetaDir(batch_dir) << "/slurm/%A_%a.log\n\n";
  s << "case \"$SLURM_ARRAY_TASK_ID\" in\n";
  for (std::size_t i = 0; i < plan.jobs.size(); ++i) {
    // The job stops its run a minute before Slurm's limit so that it can record the timeout.
    const double limit = time_limit_s > 120.0 ? time_limit_s - 60.0 : time_limit_s;
    s << "  " << i << ") exec " << JobCommandLine(binary, batch_dir, plan.jobs[i], limit) << " ;;\n";
  }
  s << "  *) echo \"planeslam batch: no job $SLURM_ARRAY_TASK_ID\" >&2; exit 2 ;;\nesac\n";
  return s.str();
}

std::string SubmitSlurm(const std::string& script, bool wait, int* array_exit_code) {
  if (FindOnPath("sbatch").empty()) {
    throw IoError("sbatch", "Slurm's sbatch is not on PATH (use --slurm --print to write the script)");
  }
  std::vector<std::string> argv = {"sbatch", "--parsable"};
  if (wait) argv.push_back("--wait");
  argv.push_back(script);
  int fds[2];
  if (::pipe(fds) != 0) throw IoError(script, "cannot create a pipe for sbatch");
  const pid_t pid = Spawn(argv, fds[1]);
  ::close(fds[1]);
  std::string out;
  char buffer[256];
  for (;;) {
    const ssize_t n = ::read(fds[0], buffer, sizeof(buffer));
    if (n > 0) out.append(buffer, static_cast<std::size_t>(n));
    else if (n == 0 || errno != EINTR) break;
  }
  ::close(fds[0]);
  const int code = WaitExitCode(pid);
  const std::string id = out.substr(0, out.find_first_of(";\n"));
  if (id.empty() || id.find_first_not_of("0123456789") != std::string::npos) {
    throw IoError(script, "sbatch refused the script (exit " + std::to_string(code) + ")");
  }
  if (array_exit_code != nullptr) *array_exit_code = code;
  return id;
}

}  // namespace planeslam::app
