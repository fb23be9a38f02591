#include "batch_manifest.hpp"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <set>
#include <sstream>

#include "cli_common.hpp"
#include "planeslam/datasets/errors.hpp"
#include "sensor_profiles.hpp"

namespace planeslam::app {
namespace {

namespace fs = std::filesystem;

/// Errors name the manifest and the line of the offending node.
class ManifestReader {
 public:
  explicit ManifestReader(std::string path) : path_(std::move(path)) {}

  [[noreturn]] void Fail(const YAML::Node& node, const std::string& reason) const {
    if (node.IsDefined() && node.Mark().line >= 0) throw IoError(path_, node.Mark().line + 1, reason);
    throw IoError(path_, reason);
  }

  void CheckKeys(const YAML::Node& map, const std::set<std::string>& allowed,
                 const std::string& what) const {
    if (!map.IsMap()) Fail(map, what + " must be a mapping");
    for (const auto& kv : map) {
      const std::string key = kv.first.as<std::string>();
      if (allowed.count(key) == 0) {
        std::string names;
        for (const auto& a : allowed) names += " " + a;
        Fail(kv.first, "unknown key '" + key + "' in " + what + " (known:" + names + ")");
      }
    }
  }

  std::string Scalar(const YAML::Node& node, const std::string& what) const {
    if (!node.IsScalar()) Fail(node, what + " must be a single value");
    return node.Scalar();
  }

  /// A file or folder named in the manifest, made absolute relative to the manifest's folder.
  std::string Path(const YAML::Node& node, const std::string& what) const {
    const fs::path p = Scalar(node, what);
    if (p.empty()) Fail(node, what + " is empty");
    const fs::path abs = p.is_absolute() ? p : fs::path(path_).parent_path() / p;
    return fs::weakly_canonical(fs::absolute(abs)).string();
  }

  std::vector<std::string> Configs(const YAML::Node& node) const {
    std::vector<std::string> files;
    if (!node) return files;
    if (node.IsScalar()) node.IsNull() ? void() : files.push_back(Path(node, "configs"));
    else if (node.IsSequence())
      for (const auto& f : node) files.push_back(Path(f, "configs"));
    else Fail(node, "configs must be a file or a list of files");
    for (const auto& f : files) {
      if (!fs::is_regular_file(f)) Fail(node, "config file " + f + " does not exist");
    }
    return files;
  }

  KeyValues Set(const YAML::Node& node) const {
    KeyValues set;
    if (!node || node.IsNull()) return set;
    if (!node.IsMap()) Fail(node, "set must be a mapping of section.key: value");
    for (const auto& kv : node) {
      set.emplace_back(Scalar(kv.first, "a set key"), Scalar(kv.second, "set value"));
    }
    return set;
  }

  /// Job and folder names: letters, digits and . _ - + = , not starting with a dot.
  void CheckName(const YAML::Node& node, const std::string& name) const {
    bool ok = !name.empty() && name[0] != '.';
    for (char c : name) {
      ok = ok && (std::isalnum(static_cast<unsigned char>(c)) || std::string("._-+=,").find(c) !=
                                                                     std::string::npos);
    }
    if (!ok) {
      Fail(node, "name '" + name + "' must be letters, digits and . _ - + = , (no '/' or spaces)");
    }
  }

  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

/// Whether `v` is selected by the name `wanted`: its own name, or its manifest entry's (which
/// selects every variant of that entry's sweep).
bool Selects(const std::string& wanted, const BatchVariant& v) {
  return wanted == v.name || (!v.entry.empty() && wanted == v.entry);
}

/// A sequence's `variants:` (one name or a list); every name must select a variant.
std::vector<std::string> ReadSelection(const ManifestReader& r, const YAML::Node& node,
                                       const std::vector<BatchVariant>& variants) {
  std::vector<std::string> names;
  if (!node) return names;
  if (node.IsScalar()) names.push_back(r.Scalar(node, "variants"));
  else if (node.IsSequence() && node.size() > 0)
    for (const auto& n : node) names.push_back(r.Scalar(n, "a variant name"));
  else r.Fail(node, "a sequence's variants must be a variant name or a non-empty list of them");
  for (const std::string& name : names) {
    bool found = false;
    for (const BatchVariant& v : variants) found = found || Selects(name, v);
    if (!found) {
      std::string known;
      for (const BatchVariant& v : variants) known += " " + v.name;
      r.Fail(node, "no variant named '" + name + "' (variants:" + known + ")");
    }
  }
  return names;
}

BatchSequence ReadSequence(const ManifestReader& r, const YAML::Node& node,
                           const std::vector<BatchVariant>& variants) {
  r.CheckKeys(node, {"path", "scene", "name", "profile", "configs", "set", "variants"},
              "a sequence");
  BatchSequence s;
  if (node["path"] && node["scene"]) r.Fail(node, "a sequence has either path or scene");
  if (node["path"]) {
    s.path = r.Path(node["path"], "path");
    if (!fs::exists(s.path)) r.Fail(node["path"], "sequence " + s.path + " does not exist");
    s.name = fs::path(s.path).filename().string();
  } else if (node["scene"]) {
    s.scene = r.Scalar(node["scene"], "scene");
    if (s.scene != "room" && s.scene != "corridor" && s.scene != "rubble") {
      r.Fail(node["scene"], "scene must be room, corridor or rubble");
    }
    s.name = s.scene;
  } else {
    r.Fail(node, "a sequence needs a path (or a built-in scene)");
  }
  if (node["name"]) s.name = r.Scalar(node["name"], "name");
  r.CheckName(node["name"] ? node["name"] : node, s.name);
  if (node["profile"]) {
    s.profile = r.Scalar(node["profile"], "profile");
    ChooseProfile(s.profile, "");  // throws naming the known profiles
  }
  s.configs = r.Configs(node["configs"]);
  s.set = r.Set(node["set"]);
  s.variants = ReadSelection(r, node["variants"], variants);
  return s;
}

/// One variant, or one per combination of its sweep's values (first key slowest).
std::vector<BatchVariant> ReadVariant(const ManifestReader& r, const YAML::Node& node) {
  r.CheckKeys(node, {"name", "configs", "set", "sweep"}, "a variant");
  BatchVariant base;
  if (node["name"]) base.name = r.Scalar(node["name"], "name");
  if (!node["name"] && !node["sweep"]) r.Fail(node, "a variant needs a name (or a sweep)");
  if (!base.name.empty()) r.CheckName(node["name"], base.name);
  base.entry = base.name;
  base.configs = r.Configs(node["configs"]);
  base.set = r.Set(node["set"]);
  std::vector<BatchVariant> variants{base};
  if (!node["sweep"]) return variants;
  const YAML::Node sweep = node["sweep"];
  if (!sweep.IsMap() || sweep.size() == 0) r.Fail(sweep, "sweep must map keys to lists of values");
  for (const auto& kv : sweep) {
    const std::string key = r.Scalar(kv.first, "a sweep key");
    if (!kv.second.IsSequence() || kv.second.size() == 0) {
      r.Fail(kv.second, "sweep values of " + key + " must be a non-empty list");
    }
    std::vector<BatchVariant> expanded;
    for (const BatchVariant& v : variants) {
      for (const auto& value_node : kv.second) {
        const std::string value = r.Scalar(value_node, "a sweep value");
        BatchVariant e = v;
        e.name += (e.name.empty() ? "" : "+") + key + "=" + value;
        r.CheckName(value_node, e.name);
        e.set.emplace_back(key, value);
        expanded.push_back(std::move(e));
      }
    }
    variants = std::move(expanded);
  }
  return variants;
}

std::vector<std::string> RunArgs(const BatchSequence& s, const BatchVariant& v, const std::vector<std::string>& configs,
                                 const KeyValues& set) {
  std::vector<std::string> args;
  if (!s.path.empty()) args.push_back(s.path);
  else args.insert(args.end(), {"--scene", s.scene});
  if (!s.profile.empty()) args.insert(args.end(), {"--sensor", s.profile});
  for (const auto* files : {&configs, &s.configs, &v.configs}) {
    for (const auto& f : *files) args.insert(args.end(), {"-c", f});
  }
  for (const auto* kvs : {&set, &s.set, &v.set}) {
    for (const auto& [k, value] : *kvs) args.insert(args.end(), {"--set", k + "=" + value});
  }
  return args;
}

/// Loads every job's configuration once so that a bad key or value stops the batch before any
/// job starts (the profile is left to `planeslam run`, which recognises it from the data).
void CheckJobConfig(const ManifestReader& r, const BatchJob& job,
                    const std::vector<std::string>& configs, const KeyValues& set) {
  ConfigOptions options;
  options.config_files = configs;
  for (const auto& [k, v] : set) options.overrides.push_back(k + "=" + v);
  try {
    LoadConfig(options);
  } catch (const ConfigError& e) {
    throw ConfigError(r.path() + ": job " + job.name + ": " + e.what());
  }
}

void BuildJobs(const ManifestReader& r, const std::vector<std::string>& configs,
               const KeyValues& set, BatchPlan* plan) {
  for (const BatchSequence& s : plan->sequences) {
    for (const BatchVariant& v : plan->variants) {
      bool selected = s.variants.empty();
      for (const std::string& wanted : s.variants) selected = selected || Selects(wanted, v);
      if (!selected) continue;
      BatchJob job;
      job.sequence = s.name;
      job.variant = v.name;
      job.name = s.name + "/" + v.name;
      job.run_args = RunArgs(s, v, configs, set);
      std::vector<std::string> all_configs = configs;
      KeyValues all_set = set;
      for (const auto* files : {&s.configs, &v.configs})
        all_configs.insert(all_configs.end(), files->begin(), files->end());
      for (const auto* kvs : {&s.set, &v.set}) all_set.insert(all_set.end(), kvs->begin(), kvs->end());
      CheckJobConfig(r, job, all_configs, all_set);
      plan->jobs.push_back(std::move(job));
    }
  }
}

SlurmOptions ReadSlurm(const ManifestReader& r, const YAML::Node& node) {
  SlurmOptions o;
  if (!node) return o;
  r.CheckKeys(node, {"partition", "account", "qos", "mem", "cpus_per_task", "max_parallel", "extra"},
              "slurm");
  if (node["partition"]) o.partition = r.Scalar(node["partition"], "partition");
  if (node["account"]) o.account = r.Scalar(node["account"], "account");
  if (node["qos"]) o.qos = r.Scalar(node["qos"], "qos");
  if (node["mem"]) o.mem = r.Scalar(node["mem"], "mem");
  try {
    if (node["cpus_per_task"]) o.cpus_per_task = node["cpus_per_task"].as<int>();
    if (node["max_parallel"]) o.max_parallel = node["max_parallel"].as<int>();
  } catch (const YAML::Exception&) {
    r.Fail(node, "cpus_per_task and max_parallel must be whole numbers");
  }
  if (o.cpus_per_task < 0 || o.max_parallel < 0) r.Fail(node, "negative slurm resources");
  if (node["extra"]) {
    if (!node["extra"].IsSequence()) r.Fail(node["extra"], "extra must be a list of sbatch options");
    for (const auto& e : node["extra"]) o.extra.push_back(r.Scalar(e, "extra"));
  }
  return o;
}

template <class T>
void CheckUnique(const ManifestReader& r, const YAML::Node& list, const std::vector<T>& items,
                 const std::string& what) {
  std::set<std::string> seen;
  for (const T& item : items) {
    if (!seen.insert(item.name).second) r.Fail(list, "two " + what + " are named " + item.name);
  }
}

YAML::Node LoadYaml(const std::string& path) {
  if (!fs::is_regular_file(path)) throw IoError(path, "no such manifest file");
  try {
    return YAML::LoadFile(path);
  } catch (const YAML::ParserException& e) {
    throw IoError(path, e.mark.line + 1, "not valid YAML: " + e.msg);
  } catch (const YAML::Exception& e) {
    throw IoError(path, std::string("cannot be read: ") + e.what());
  }
}

}  // namespace

BatchPlan LoadBatchManifest(const std::string& path) {
  BatchPlan plan;
  plan.manifest = fs::absolute(path).lexically_normal().string();
  const ManifestReader r(plan.manifest);
  const YAML::Node root = LoadYaml(plan.manifest);
  if (!root.IsMap()) r.Fail(root, "a manifest is a mapping with sequences: and variants:");
  r.CheckKeys(root, {"sequences", "variants", "configs", "set", "time_limit", "slurm"},
              "the manifest");
  const YAML::Node seqs = root["sequences"];
  if (!seqs || !seqs.IsSequence() || seqs.size() == 0) {
    r.Fail(seqs ? seqs : root, "sequences: must list at least one sequence");
  }
  const YAML::Node vars = root["variants"];
  if (vars && !vars.IsNull()) {
    if (!vars.IsSequence() || vars.size() == 0) r.Fail(vars, "variants: must be a non-empty list");
    for (const auto& v : vars) {
      for (auto& e : ReadVariant(r, v)) plan.variants.push_back(std::move(e));
    }
    CheckUnique(r, vars, plan.variants, "variants");
  } else {
    plan.variants.push_back({"default", {}, {}, "default"});
  }
  for (const auto& s : seqs) plan.sequences.push_back(ReadSequence(r, s, plan.variants));
  CheckUnique(r, seqs, plan.sequences, "sequences");
  if (root["time_limit"]) {
    plan.time_limit_s = ParseTimeLimit(r.Scalar(root["time_limit"], "time_limit"),
                                       plan.manifest + ": time_limit");
  }
  plan.slurm = ReadSlurm(r, root["slurm"]);
  BuildJobs(r, r.Configs(root["configs"]), r.Set(root["set"]), &plan);
  return plan;
}

double ParseTimeLimit(const std::string& text, const std::string& where) {
  // Slurm's forms: minutes, MM:SS, HH:MM:SS, D-HH, D-HH:MM, D-HH:MM:SS.
  int days = 0;
  std::string rest = text;
  const auto dash = text.find('-');
  std::vector<long> parts;
  try {
    if (dash != std::string::npos) {
      days = std::stoi(text.substr(0, dash));
      rest = text.substr(dash + 1);
    }
    std::stringstream ss(rest);
    std::string part;
    while (std::getline(ss, part, ':')) {
      std::size_t used = 0;
      parts.push_back(std::stol(part, &used));
      if (used != part.size() || parts.back() < 0) throw std::invalid_argument(part);
    }
  } catch (const std::exception&) {
    parts.clear();
  }
  double s = -1.0;
  if (dash != std::string::npos && !parts.empty() && parts.size() <= 3) {
    s = days * 86400.0 + parts[0] * 3600.0 + (parts.size() > 1 ? parts[1] * 60.0 : 0.0) +
        (parts.size() > 2 ? parts[2] : 0.0);
  } else if (dash == std::string::npos && parts.size() == 1) {
    s = parts[0] * 60.0;
  } else if (dash == std::string::npos && parts.size() == 2) {
    s = parts[0] * 60.0 + parts[1];
  } else if (dash == std::string::npos && parts.size() == 3) {
    s = parts[0] * 3600.0 + parts[1] * 60.0 + parts[2];
  }
  if (!(s > 0.0) || days < 0) {
    throw ConfigError(where + ": '" + text +
                      "' is not a time limit (minutes, MM:SS, HH:MM:SS or D-HH:MM:SS)");
  }
  return s;
}

std::string FormatSlurmTime(double seconds) {
  const long minutes = std::max(1L, static_cast<long>(std::ceil(seconds / 60.0)));
  char buffer[48];
  std::snprintf(buffer, sizeof(buffer), "%ld-%02ld:%02ld:00", minutes / 1440, (minutes / 60) % 24,
                minutes % 60);
  return buffer;
}

std::string ShellQuote(const std::string& arg) {
  const bool plain = !arg.empty() && arg.find_first_not_of(
                                         "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ"
                                         "0123456789_-+=.,/:@%") == std::string::npos;
  if (plain) return arg;
  std::string quoted = "'";
  for (char c : arg) quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return quoted + "'";
}

std::string ShellJoin(const std::vector<std::string>& args) {
  std::string line;
  for (const auto& a : args) line += (line.empty() ? "" : " ") + ShellQuote(a);
  return line;
}

}  // namespace planeslam::app
