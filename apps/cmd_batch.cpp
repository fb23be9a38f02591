// `planeslam batch MANIFEST --out DIR`: every sequence of a manifest under every variant, one
// `planeslam run` per job, dispatched by GNU parallel on this machine or as a Slurm job array;
// `planeslam batch collect DIR` tables and plots the results.
#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include "batch_collect.hpp"
#include "batch_dispatch.hpp"
#include "batch_job.hpp"
#include "batch_manifest.hpp"
#include "cli_common.hpp"
#include "command_registry.hpp"
#include "exit_codes.hpp"
#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/errors.hpp"

namespace planeslam::app {
namespace {

namespace fs = std::filesystem;
namespace ds = planeslam::datasets;

std::string SelfBinary() {
  std::error_code ec;
  const fs::path self = fs::read_symlink("/proc/self/exe", ec);
  if (ec) throw IoError("/proc/self/exe", "cannot tell where the planeslam executable is");
  return self.string();
}

/// Holds DIR/.batch/lock for the life of the process (closed on exec, released when it dies), so
/// two local batches never work in one folder at once.
void LockBatchDir(const std::string& meta) {
  const std::string path = meta + "/lock";
  const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) throw IoError(path, "cannot create the batch's lock file");
  if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
    throw IoError(path, "another planeslam batch is running in this folder");
  }
}

const char* StateName(JobState s) {
  switch (s) {
    case JobState::kComplete: return "complete";
    case JobState::kOutdated: return "outdated";
    case JobState::kFailed: return "failed";
    case JobState::kMissing: return "to run";
  }
  return "";
}

/// "9 jobs (3 sequences x 3 variants)", or "... , not every sequence under every variant)".
std::string JobCount(const BatchPlan& plan) {
  const std::size_t product = plan.sequences.size() * plan.variants.size();
  return std::to_string(plan.jobs.size()) + " jobs (" + std::to_string(plan.sequences.size()) +
         " sequences x " + std::to_string(plan.variants.size()) + " variants" +
         (plan.jobs.size() < product ? ", not every sequence under every variant)" : ")");
}

class BatchCommand : public Command {
 public:
  std::string Name() const override { return "batch"; }
  std::string Summary() const override {
    return "Sequences x variants of a manifest, via GNU parallel or Slurm; collect compares them";
  }
  int Order() const override { return 45; }

  void Setup(CLI::App& sub) override {
    sub.add_option("MANIFEST", manifest_, "YAML manifest: sequences, variants (see below)");
    sub.add_option("-o,--out", out_, "output folder: DIR/<sequence>/<variant>/ per job");
    sub.add_flag("--dry-run", dry_run_, "list the jobs, their state and their command lines");
    sub.add_option("-j,--jobs", jobs_, "jobs at once (local: default one per core; Slurm: array "
                                       "throttle, default slurm.max_parallel)")
        ->check(CLI::Range(1, 100000));
    sub.add_option("--time-limit", time_limit_,
                   "per job: minutes, HH:MM:SS or D-HH:MM:SS (default: the manifest's time_limit)");
    sub.add_flag("--slurm", slurm_, "submit a Slurm job array with sbatch instead of running here");
    sub.add_flag("--print", print_, "with --slurm: write and print the script, do not submit it");
    sub.add_flag("--wait", wait_, "with --slurm: wait until the array has finished (sbatch --wait)");
    sub.add_option("--partition", partition_, "with --slurm: partition (default: the manifest's)");
    sub.add_option("--mem", mem_, "with --slurm: memory per job, e.g. 4G");
    sub.add_option("--cpus-per-task", cpus_, "with --slurm: cores per job")->check(CLI::Range(1, 4096));
    collect_ = sub.add_subcommand("collect", "One table (Markdown, CSV, JSON) and SVG plots of a "
                                             "batch's results");
    collect_->add_option("DIR", collect_dir_, "the batch's output folder")->required();
    job_ = sub.add_subcommand("job", "");  // internal: what parallel and Slurm run per job
    job_->group("");
    job_->add_option("DIR", job_dir_)->required();
    job_->add_option("NAME", job_name_)->required();
    job_->add_option("--time-limit", job_time_limit_);
    job_->add_option("COMMAND", job_command_)->required();
    sub.footer(Footer());
  }

  int Run() override {
    try {
      return Dispatch();
    } catch (const fs::filesystem_error& e) {
      throw IoError(e.path1().string(), e.code().message());
    }
  }

 private:
  int Dispatch() {
    if (collect_->parsed()) return Collect(collect_dir_);
    if (job_->parsed()) {
      return RunBatchJob(fs::absolute(job_dir_).string(), job_name_, job_time_limit_, job_command_);
    }
    if (manifest_.empty()) throw ConfigError("batch: give a MANIFEST (see planeslam batch --help)");
    BatchPlan plan = LoadBatchManifest(manifest_);
    if (!time_limit_.empty()) plan.time_limit_s = ParseTimeLimit(time_limit_, "--time-limit");
    if (out_.empty()) throw ConfigError("batch: --out DIR is required");
    if ((print_ || wait_) && !slurm_) throw ConfigError("batch: --print and --wait go with --slurm");
    const std::string dir = fs::absolute(out_).lexically_normal().string();
    const std::string binary = SelfBinary();
    std::vector<std::size_t> pending;
    std::vector<JobStatus> states;
    for (std::size_t i = 0; i < plan.jobs.size(); ++i) {
      states.push_back(ReadJobStatus(dir, plan.jobs[i]));
      if (states.back().state != JobState::kComplete) pending.push_back(i);
    }
    if (dry_run_) return DryRun(plan, binary, dir, states);

    const std::string meta = BatchMetaDir(dir);
    EnsureDirectory(meta);
    ds::WriteFileAtomic(meta + "/jobs.json", PlanJson(plan, binary, dir).dump(2) + "\n");
    std::cout << "planeslam batch: " << JobCount(plan) << ", "
              << plan.jobs.size() - pending.size() << " complete, " << pending.size()
              << " to run; outputs in " << dir << "/\n";
    if (slurm_) return Slurm(plan, binary, dir, pending);
    LockBatchDir(meta);
    RemoveStaleAttempts(dir, plan.jobs);
    int code = kExitSuccess;
    if (!pending.empty()) code = RunWithParallel(plan, binary, dir, pending, jobs_);
    const int failures = Report(plan, dir);
    if (code == kExitInterrupted) {
      std::cout << "interrupted: finished jobs are kept; run the same command again to complete "
                   "the rest\n";
      return kExitInterrupted;
    }
    return failures == 0 ? kExitSuccess : kExitError;
  }

  static std::string Footer() {
    return "Manifest (paths relative to it; each job runs planeslam run SEQUENCE [--sensor P] "
           "[-c F]... [--set K=V]...):\n"
           "  sequences:\n"
           "    - path: data/room            # name: folder name; profile: as planeslam run "
           "chooses\n"
           "    - {path: data/fr3, name: fr3, profile: tum_fr3, configs: [my.yaml], set: "
           "{run.max_frames: 300}}\n"
           "    - {path: data/lab, variants: [default, theta]}   # only under these (default: "
           "all)\n"
           "  variants:                      # default: one variant 'default'\n"
           "    - name: default\n"
           "    - name: fast\n"
           "      set: {detection.method: grid-fast}\n"
           "    - name: theta                # sweep: one variant per value, theta+detection.theta=200 ...\n"
           "      sweep: {detection.theta: [200, 400, 800]}\n"
           "  set: {octomap.enabled: false}  # every job (configs: too)\n"
           "  time_limit: \"00:30:00\"         # per job\n"
           "  slurm: {partition: cpu, cpus_per_task: 1, mem: 4G, max_parallel: 16, extra: "
           "[\"--qos=normal\"]}\n"
           "A job's folder DIR/<sequence>/<variant>/ appears only when its run completed (written "
           "in a\ntemporary sibling, then renamed); a failed attempt goes to DIR/.batch/failed/ "
           "with its\nstdout.log, stderr.log and job.json. Running the batch again skips complete "
           "jobs and\nreruns failed, missing and outdated (settings changed) ones.\n"
           "Exit codes: 0 every job complete; 2 a job failed or bad input; 130 interrupted.\n\n"
           "Examples:\n"
           "  planeslam batch sweep.yaml --out sweep --dry-run\n"
           "  planeslam batch sweep.yaml --out sweep --jobs 4     GNU parallel on this machine\n"
           "  planeslam batch sweep.yaml --out sweep --slurm      submit a job array (sbatch)\n"
           "  planeslam batch sweep.yaml --out sweep --slurm --print   only write the script\n"
           "  planeslam batch collect sweep                       results.{md,csv,json}, "
           "compare_*.svg";
  }

  int DryRun(const BatchPlan& plan, const std::string& binary, const std::string& dir,
             const std::vector<JobStatus>& states) const {
    std::cout << JobCount(plan) << ", outputs in " << dir << "/\n";
    for (std::size_t i = 0; i < plan.jobs.size(); ++i) {
      std::cout << plan.jobs[i].name << " [" << StateName(states[i].state) << "]\n  "
                << RunCommandLine(binary, dir, plan.jobs[i]) << "\n";
    }
    return kExitSuccess;
  }

  int Slurm(const BatchPlan& plan, const std::string& binary, const std::string& dir,
            const std::vector<std::size_t>& pending) {
    SlurmOptions options = plan.slurm;
    if (!partition_.empty()) options.partition = partition_;
    if (!mem_.empty()) options.mem = mem_;
    if (cpus_ > 0) options.cpus_per_task = cpus_;
    if (jobs_ > 0) options.max_parallel = jobs_;
    if (pending.empty()) {
      Report(plan, dir);
      return kExitSuccess;
    }
    const std::string meta = BatchMetaDir(dir);
    EnsureDirectory(meta + "/slurm");
    const std::string script = meta + "/slurm/batch.sbatch";
    const std::string text = SlurmScript(plan, binary, dir, pending, options, plan.time_limit_s);
    ds::WriteFileAtomic(script, text);
    if (print_) {
      std::cout << text << "(written to " << script << "; submit with: sbatch " << script << ")\n";
      return kExitSuccess;
    }
    RemoveStaleAttempts(dir, plan.jobs);
    int array_code = 0;
    const std::string id = SubmitSlurm(script, wait_, &array_code);
    std::cout << "submitted Slurm job array " << id << " (" << pending.size() << " tasks, script "
              << script << ")\n";
    if (!wait_) {
      std::cout << "when it has finished: planeslam batch collect " << dir << "\n";
      return kExitSuccess;
    }
    return Report(plan, dir) == 0 ? kExitSuccess : kExitError;
  }

  /// Prints the jobs that are not complete with their errors; returns how many.
  static int Report(const BatchPlan& plan, const std::string& dir) {
    int complete = 0, problems = 0;
    for (const BatchJob& job : plan.jobs) {
      const JobStatus s = ReadJobStatus(dir, job);
      if (s.state == JobState::kComplete) {
        ++complete;
        continue;
      }
      ++problems;
      std::cout << "  not complete: " << job.name << ": "
                << (s.state == JobState::kOutdated ? "outdated" : s.Error()) << "\n";
    }
    std::cout << complete << " of " << plan.jobs.size() << " jobs complete";
    if (problems > 0) std::cout << ", " << problems << " not (failed attempts in " << dir << "/.batch/failed/)";
    std::cout << "; tables and plots: planeslam batch collect " << dir << "\n";
    return problems;
  }

  static int Collect(const std::string& dir_option) {
    const std::string dir = fs::absolute(dir_option).lexically_normal().string();
    const CollectOutput out = CollectBatch(dir);
    std::cout << out.markdown << "\n" << out.complete << " complete, " << out.failed << " failed, "
              << out.missing << " not run; written:";
    for (const auto& f : out.files) std::cout << " " << fs::path(f).filename().string();
    std::cout << " in " << dir << "/\n";
    return kExitSuccess;
  }

  std::string manifest_, out_, time_limit_, partition_, mem_;
  int jobs_ = 0, cpus_ = 0;
  bool dry_run_ = false, slurm_ = false, print_ = false, wait_ = false;
  CLI::App* collect_ = nullptr;
  CLI::App* job_ = nullptr;
  std::string collect_dir_, job_dir_, job_name_;
  double job_time_limit_ = 0.0;
  std::vector<std::string> job_command_;
};

PLANESLAM_REGISTER_COMMAND(BatchCommand);

}  // namespace
}  // namespace planeslam::app
