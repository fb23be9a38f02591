#pragma once
/// One job of a batch and where it stands in the batch's output folder DIR.
///
/// A job runs `planeslam run ... --out DIR/<seq>/.<variant>.tmp.<host>.<pid>` (a hidden sibling on
/// the same file system), then writes job.json (its arguments, exit code, status, error) there and
/// renames the folder to DIR/<seq>/<variant> when the run completed (exit 0, or 5: completed with
/// skipped frames), else to DIR/.batch/failed/<seq>/<variant>. So DIR/<seq>/<variant> is complete
/// or absent whatever kills the job, the batch or the machine; a folder whose job.json holds other
/// arguments than the manifest's is outdated and rerun.
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "batch_manifest.hpp"

namespace planeslam::app {

enum class JobState {
  kComplete,  ///< DIR/<job> exists with the manifest's arguments
  kOutdated,  ///< DIR/<job> exists, made with other arguments
  kFailed,    ///< the last attempt failed (DIR/.batch/failed/<job>)
  kMissing,   ///< never run, or interrupted before it could record anything
};

struct JobStatus {
  JobState state = JobState::kMissing;
  nlohmann::json record;  ///< job.json of the folder or of the failed attempt (null when missing)
  std::string Error() const;  ///< "exit 2: <last line of stderr>" for a failed job
};

/// The batch's bookkeeping folder DIR/.batch.
std::string BatchMetaDir(const std::string& batch_dir);

JobStatus ReadJobStatus(const std::string& batch_dir, const BatchJob& job);

/// Removes the temporary folders of attempts on this host whose process is gone.
void RemoveStaleAttempts(const std::string& batch_dir, const std::vector<BatchJob>& jobs);

/// What `planeslam batch job` runs: `command` (planeslam run and its arguments, without --out)
/// for the job `name` ("<seq>/<variant>") of `batch_dir`, stopping it after `time_limit_s`
/// (0: none). Prints one line; returns 0 when the job is complete, else its failure's exit code.
int RunBatchJob(const std::string& batch_dir, const std::string& name, double time_limit_s,
                const std::vector<std::string>& command);

}  // namespace planeslam::app
