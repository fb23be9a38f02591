#pragma once
/// The batch manifest of `planeslam batch`: sequences x variants, each job one `planeslam run`.
///
///   sequences:                  # each: path (folder, relative to the manifest) or scene
///     - path: room              #   (built-in synthetic scene); name (default: the folder's name),
///       profile: tum_fr3        #   profile (--sensor; default: recognised), configs, set,
///       variants: [default]     #   variants (the names it runs under; default: every variant)
///   variants:                   # each: name, configs, set, sweep {key: [values]} (one variant
///     - name: default           #   per combination, named name+key=value...); default: one
///     - name: fast              #   variant "default" without overrides
///       set: {detection.method: grid-fast}
///   set: {octomap.enabled: false}   # applied to every job (so are configs:)
///   time_limit: "00:30:00"      # per job, [D-]HH:MM:SS or minutes (local and Slurm)
///   slurm: {partition: p, cpus_per_task: 1, mem: 4G, max_parallel: 8, extra: [--qos=normal]}
///
/// The batch is the product of sequences and variants, less the pairs a sequence's `variants:`
/// leaves out; a name there selects a variant, or every variant its sweep made from one entry.
///
/// A job's arguments: the sequence, --sensor, -c files (global, sequence, variant), then --set
/// overrides (global, sequence, variant, sweep); later overrides win.
#include <string>
#include <utility>
#include <vector>

namespace planeslam::app {

using KeyValues = std::vector<std::pair<std::string, std::string>>;

struct BatchSequence {
  std::string name;
  std::string path;   ///< absolute folder, empty for a built-in scene
  std::string scene;  ///< built-in synthetic scene when no path
  std::string profile;
  std::vector<std::string> configs;  ///< absolute
  KeyValues set;
  std::vector<std::string> variants;  ///< names of the variants it runs under; empty: all
};

/// One variant after sweep expansion.
struct BatchVariant {
  std::string name;
  std::vector<std::string> configs;  ///< absolute
  KeyValues set;
  std::string entry;  ///< the name of the manifest entry it came from ("" for an unnamed sweep)
};

/// sbatch resources; empty / zero: the cluster's defaults.
struct SlurmOptions {
  std::string partition, account, qos, mem;
  int cpus_per_task = 0;
  int max_parallel = 0;  ///< array throttle "%N"
  std::vector<std::string> extra;  ///< further sbatch options, e.g. "--constraint=avx2"
};

struct BatchJob {
  std::string name;  ///< "<sequence>/<variant>", also its folder under the batch's output
  std::string sequence, variant;
  /// The arguments after `planeslam run` except --out.
  std::vector<std::string> run_args;
};

struct BatchPlan {
  std::string manifest;  ///< absolute path
  std::vector<BatchSequence> sequences;
  std::vector<BatchVariant> variants;
  std::vector<BatchJob> jobs;  ///< sequence-major, in the manifest's order
  double time_limit_s = 0.0;   ///< 0 = none
  SlurmOptions slurm;
};

/// Reads and checks `path`: unknown keys, missing sequences, duplicate names, bad names, a bad
/// override (every job's configuration is loaded once) throw ConfigError / IoError naming the
/// manifest, the line and the problem.
BatchPlan LoadBatchManifest(const std::string& path);

/// "[D-]HH:MM:SS", "MM:SS" or whole minutes (Slurm's forms) in seconds; throws ConfigError.
double ParseTimeLimit(const std::string& text, const std::string& where);
/// Seconds as Slurm's "D-HH:MM:SS" (rounded up to whole minutes, at least one).
std::string FormatSlurmTime(double seconds);

/// `arg` quoted for a POSIX shell when it needs it.
std::string ShellQuote(const std::string& arg);
std::string ShellJoin(const std::vector<std::string>& args);

}  // namespace planeslam::app
