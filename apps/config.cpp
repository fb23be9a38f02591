#include "config.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <set>
#include <sstream>

namespace planeslam::app {

std::vector<SectionInfo>& ConfigSectionRegistry() {
  static std::vector<SectionInfo> registry;
  return registry;
}

namespace {

std::string FormatDouble(double v) {
  std::ostringstream os;
  os << std::setprecision(std::numeric_limits<double>::max_digits10 - 2) << v;
  return os.str();
}

std::string Quote(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + "\"";
}

/// A mapping key as text; YAML also allows sequences and mappings as keys ("? [a]: 1"), which
/// no config key is.
std::string PlainKey(const YAML::Node& key, const std::string& where) {
  if (!key.IsScalar()) {
    throw ConfigError(where + ":" + std::to_string(key.Mark().line + 1) +
                      ": a key must be a plain name, not a list or mapping");
  }
  return key.Scalar();
}

/// Applies one YAML mapping to one section, checking every key.
class YamlLoader : public FieldVisitor {
 public:
  YamlLoader(const YAML::Node& node, std::string origin, std::string section)
      : node_(node), origin_(std::move(origin)), section_(std::move(section)) {}

  void Field(const std::string& key, double& value, const std::string&, double min,
             double max) override {
    const YAML::Node n = Take(key);
    if (!n) return;
    double v = 0;
    if (!n.IsScalar() || !YAML::convert<double>::decode(n, v) || !IsNumber(n.Scalar())) {
      Fail(key, "expected a number, got '" + Text(n) + "'");
    }
    if (!std::isfinite(v)) Fail(key, "must be finite");
    if (v < min || v > max) {
      Fail(key, FormatDouble(v) + " is out of range [" + FormatDouble(min) + ", " +
                    FormatDouble(max) + "]");
    }
    value = v;
  }
  void Field(const std::string& key, int& value, const std::string&, int min, int max) override {
    const YAML::Node n = Take(key);
    if (!n) return;
    long long v = 0;
    if (!n.IsScalar() || !YAML::convert<long long>::decode(n, v)) {
      Fail(key, "expected an integer, got '" + Text(n) + "'");
    }
    if (v < min || v > max) {
      Fail(key, std::to_string(v) + " is out of range [" + std::to_string(min) + ", " +
                    std::to_string(max) + "]");
    }
    value = static_cast<int>(v);
  }
  void Field(const std::string& key, bool& value, const std::string&) override {
    const YAML::Node n = Take(key);
    if (!n) return;
    bool v = false;
    if (!n.IsScalar() || !YAML::convert<bool>::decode(n, v)) {
      Fail(key, "expected true or false, got '" + Text(n) + "'");
    }
    value = v;
  }
  void Field(const std::string& key, std::string& value, const std::string&,
             const std::vector<std::string>& choices) override {
    const YAML::Node n = Take(key);
    if (!n) return;
    if (!n.IsScalar()) Fail(key, "expected a string");
    const std::string v = n.Scalar();
    if (!choices.empty() && std::find(choices.begin(), choices.end(), v) == choices.end()) {
      std::string list;
      for (const auto& c : choices) list += (list.empty() ? "" : ", ") + c;
      Fail(key, "'" + v + "' is not one of: " + list);
    }
    value = v;
  }

  /// Keys present in the YAML but never asked for by the section.
  void CheckNoUnknownKeys() const {
    for (const auto& kv : node_) {
      const std::string key = PlainKey(kv.first, origin_ + ": section '" + section_ + "'");
      if (!seen_.count(key)) Fail(key, "unknown key");
    }
  }

 private:
  static bool IsNumber(const std::string& s) {
    // yaml-cpp's double decode accepts "inf"/"nan" spellings; numbers must be numerals here.
    return !s.empty() && s.find_first_not_of("0123456789+-.eE") == std::string::npos;
  }
  static std::string Text(const YAML::Node& n) {
    if (n.IsScalar()) return n.Scalar();
    std::ostringstream os;
    os << n;
    std::string s = os.str();
    std::replace(s.begin(), s.end(), '\n', ' ');
    return s;
  }
  YAML::Node Take(const std::string& key) {
    seen_.insert(key);
    return node_[key];
  }
  [[noreturn]] void Fail(const std::string& key, const std::string& reason) const {
    throw ConfigError(origin_ + ": key '" + section_ + "." + key + "': " + reason);
  }

  const YAML::Node& node_;
  std::string origin_;
  std::string section_;
  std::set<std::string> seen_;
};

/// Writes the fields of one section as YAML with comments.
class YamlDumper : public FieldVisitor {
 public:
  YamlDumper(std::ostream& os, bool docs) : os_(os), docs_(docs) {}
  void Field(const std::string& key, double& value, const std::string& doc, double min,
             double max) override {
    Line(key, FormatDouble(value), doc, "[" + FormatDouble(min) + ", " + FormatDouble(max) + "]");
  }
  void Field(const std::string& key, int& value, const std::string& doc, int min,
             int max) override {
    Line(key, std::to_string(value), doc,
         "[" + std::to_string(min) + ", " + std::to_string(max) + "]");
  }
  void Field(const std::string& key, bool& value, const std::string& doc) override {
    Line(key, value ? "true" : "false", doc, "");
  }
  void Field(const std::string& key, std::string& value, const std::string& doc,
             const std::vector<std::string>& choices) override {
    std::string range;
    for (const auto& c : choices) range += (range.empty() ? "one of: " : ", ") + c;
    Line(key, Quote(value), doc, range);
  }

 private:
  void Line(const std::string& key, const std::string& value, const std::string& doc,
            const std::string& range) {
    std::string text = "  " + key + ": " + value;
    if (docs_ && (!doc.empty() || !range.empty())) {
      text.resize(std::max<std::size_t>(text.size(), 36), ' ');
      text += "  # " + doc + (range.empty() ? "" : (doc.empty() ? "" : " ") + range);
    }
    os_ << text << "\n";
  }
  std::ostream& os_;
  bool docs_;
};

}  // namespace

Config::Config() {
  std::vector<const SectionInfo*> infos;
  for (const auto& info : ConfigSectionRegistry()) infos.push_back(&info);
  // Registration order follows link order; sort so dumps are stable.
  std::sort(infos.begin(), infos.end(),
            [](const SectionInfo* a, const SectionInfo* b) { return a->name < b->name; });
  for (const SectionInfo* info : infos) sections_.emplace_back(info, info->make());
}

void* Config::Find(const std::string& name, std::type_index type) {
  for (auto& [info, data] : sections_) {
    if (info->name == name) {
      PLANESLAM_CHECK(info->type == type, "config section '" << name << "' has another type");
      return data.get();
    }
  }
  PLANESLAM_CHECK(false, "no config section '" << name << "'");
  return nullptr;
}

void Config::LoadFile(const std::string& path) {
  if (!std::filesystem::is_regular_file(path)) throw IoError(path, "no such file");
  std::ifstream in(path);
  if (!in) throw IoError(path, "cannot open file");
  std::stringstream ss;
  ss << in.rdbuf();
  LoadString(ss.str(), path);
  sources_.push_back(path);
}

void Config::LoadString(const std::string& yaml, const std::string& origin) {
  YAML::Node root;
  try {
    root = YAML::Load(yaml);
  } catch (const YAML::Exception& e) {
    throw ConfigError(origin + ":" + std::to_string(e.mark.line + 1) + ": not valid YAML: " + e.msg);
  }
  if (root.IsNull()) return;  // an empty file changes nothing
  if (!root.IsMap()) throw ConfigError(origin + ": expected a mapping of sections at the top level");
  for (const auto& kv : root) {
    const std::string name = PlainKey(kv.first, origin);
    auto it = std::find_if(sections_.begin(), sections_.end(),
                           [&](const auto& s) { return s.first->name == name; });
    if (it == sections_.end()) throw ConfigError(origin + ": key '" + name + "': unknown section");
    if (kv.second.IsNull()) continue;
    if (!kv.second.IsMap()) {
      throw ConfigError(origin + ": key '" + name + "': expected a mapping of keys");
    }
    // Load into a copy so a failure leaves the config unchanged.
    std::shared_ptr<void> copy = it->first->clone(it->second.get());
    YamlLoader loader(kv.second, origin, name);
    it->first->visit(loader, copy.get());
    loader.CheckNoUnknownKeys();
    if (it->first->validate) {
      const auto problems = it->first->validate(copy.get());
      if (!problems.empty()) throw ConfigError(origin + ": section '" + name + "': " + problems[0]);
    }
    it->second = copy;
  }
}

void Config::Set(const std::string& assignment) {
  const auto eq = assignment.find('=');
  const auto dot = assignment.find('.');
  if (eq == std::string::npos || dot == std::string::npos || dot > eq) {
    throw ConfigError("--set '" + assignment + "': expected section.key=value");
  }
  const std::string yaml = assignment.substr(0, dot) + ":\n  " +
                           assignment.substr(dot + 1, eq - dot - 1) + ": " +
                           assignment.substr(eq + 1) + "\n";
  LoadString(yaml, "--set");
}

std::string Config::ToYaml(bool with_docs) const {
  std::ostringstream os;
  bool first = true;
  for (const auto& [info, data] : sections_) {
    if (!first) os << "\n";
    first = false;
    if (with_docs && !info->doc.empty()) os << "# " << info->doc << "\n";
    os << info->name << ":\n";
    YamlDumper dumper(os, with_docs);
    info->visit(dumper, data.get());
  }
  return os.str();
}

}  // namespace planeslam::app
