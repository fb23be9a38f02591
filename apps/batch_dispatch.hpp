#pragma once
/// Dispatch of a batch's jobs by existing engines: GNU parallel on this machine, a Slurm job array
/// on a cluster. Both execute the same line per job, `planeslam-batch-job DIR NAME -- planeslam
/// run ARGS` (batch_job.hpp; `planeslam batch job` when that executable is not beside planeslam),
/// so a job behaves alike wherever it runs.
#include <cstddef>
#include <string>
#include <vector>

#include "batch_manifest.hpp"

namespace planeslam::app {

/// The line GNU parallel or the Slurm script runs for `job`.
std::string JobCommandLine(const std::string& binary, const std::string& batch_dir,
                           const BatchJob& job, double time_limit_s);

/// The job's `planeslam run` line as a user would type it (outputs straight into its folder).
std::string RunCommandLine(const std::string& binary, const std::string& batch_dir,
                           const BatchJob& job);

/// Runs the jobs `pending` (indices into plan.jobs) through GNU parallel with `jobs` at once
/// (0: one per core) and waits. SIGINT/SIGTERM to the batch stop the jobs running (recorded as
/// interrupted) and return kExitInterrupted; a batch killed outright takes parallel with it.
/// Throws IoError when GNU parallel is missing.
int RunWithParallel(const BatchPlan& plan, const std::string& binary, const std::string& batch_dir,
                    const std::vector<std::size_t>& pending, int jobs);

/// The sbatch script of a job array over `pending` (task i runs plan.jobs[i]).
std::string SlurmScript(const BatchPlan& plan, const std::string& binary,
                        const std::string& batch_dir, const std::vector<std::size_t>& pending,
                        const SlurmOptions& slurm, double time_limit_s);

/// `sbatch --parsable [--wait] script`; returns the job id. Throws IoError when sbatch fails.
std::string SubmitSlurm(const std::string& script, bool wait, int* array_exit_code);

/// The first executable `name` on PATH, "" when none.
std::string FindOnPath(const std::string& name);

}  // namespace planeslam::app
