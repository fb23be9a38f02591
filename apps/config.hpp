#pragma once
/// YAML configuration mirrored onto the modules' plain config structs.
///
/// Each module config struct is registered once as a section (PLANESLAM_REGISTER_CONFIG_SECTION in
/// apps/config_sections*.cpp) with a function that visits its fields: key, unit/doc comment and the
/// allowed range. Loading a YAML file checks every key against the sections: an unknown key, a wrong
/// type or an out-of-range value throws ConfigError naming the file, the key and the reason.
/// ToYaml() dumps the effective configuration with comments: config/reference.yaml is that dump
/// of the defaults.
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <typeindex>
#include <vector>

#include "planeslam/datasets/errors.hpp"

namespace planeslam::app {

/// Visits the fields of one config struct (loading, dumping and validating share this).
class FieldVisitor {
 public:
  virtual ~FieldVisitor() = default;
  virtual void Field(const std::string& key, double& value, const std::string& doc, double min,
                     double max) = 0;
  virtual void Field(const std::string& key, int& value, const std::string& doc, int min,
                     int max) = 0;
  virtual void Field(const std::string& key, bool& value, const std::string& doc) = 0;
  /// `choices` empty = any string.
  virtual void Field(const std::string& key, std::string& value, const std::string& doc,
                     const std::vector<std::string>& choices) = 0;
};

struct SectionInfo {
  std::string name;  ///< YAML top-level key
  std::string doc;   ///< comment above the section
  std::type_index type = typeid(void);
  std::function<std::shared_ptr<void>()> make;
  std::function<std::shared_ptr<void>(const void*)> clone;
  std::function<void(FieldVisitor&, void*)> visit;
  /// Cross-field checks (e.g. min < max); returns problems, empty when fine.
  std::function<std::vector<std::string>(const void*)> validate;
};

std::vector<SectionInfo>& ConfigSectionRegistry();

template <class T>
struct ConfigSectionRegistrar {
  ConfigSectionRegistrar(std::string name, std::string doc, void (*visit)(FieldVisitor&, T&),
                         std::vector<std::string> (*validate)(const T&) = nullptr) {
    SectionInfo info;
    info.name = std::move(name);
    info.doc = std::move(doc);
    info.type = typeid(T);
    info.make = [] { return std::make_shared<T>(); };
    info.clone = [](const void* p) { return std::make_shared<T>(*static_cast<const T*>(p)); };
    info.visit = [visit](FieldVisitor& v, void* p) { visit(v, *static_cast<T*>(p)); };
    if (validate) {
      info.validate = [validate](const void* p) { return validate(*static_cast<const T*>(p)); };
    }
    ConfigSectionRegistry().push_back(std::move(info));
  }
};

/// All sections at their defaults, then overridden by files and --set values.
class Config {
 public:
  Config();

  /// The struct of section `name`; throws CheckError when the section or type is wrong (a bug).
  template <class T>
  T& Get(const std::string& name) {
    return *static_cast<T*>(Find(name, typeid(T)));
  }
  template <class T>
  const T& Get(const std::string& name) const {
    return *static_cast<const T*>(const_cast<Config*>(this)->Find(name, typeid(T)));
  }

  /// Applies a YAML file on top of the current values. Throws ConfigError ("FILE: key 'a.b': ...")
  /// or IoError when the file is missing or not YAML.
  void LoadFile(const std::string& path);
  /// Applies YAML text (`origin` names it in messages).
  void LoadString(const std::string& yaml, const std::string& origin);
  /// Applies one override "section.key=value" (from --set).
  void Set(const std::string& assignment);
  /// The effective configuration as YAML, with units and ranges as comments when `with_docs`.
  std::string ToYaml(bool with_docs = true) const;
  /// Files applied so far, in order.
  const std::vector<std::string>& sources() const { return sources_; }

 private:
  void* Find(const std::string& name, std::type_index type);
  std::vector<std::pair<const SectionInfo*, std::shared_ptr<void>>> sections_;
  std::vector<std::string> sources_;
};

}  // namespace planeslam::app

#define PLANESLAM_CONFIG_CONCAT2(a, b) a##b
#define PLANESLAM_CONFIG_CONCAT(a, b) PLANESLAM_CONFIG_CONCAT2(a, b)
/// Registers `Type` as YAML section `name` visited by `visit_fn` (and optional `validate_fn`).
#define PLANESLAM_REGISTER_CONFIG_SECTION(Type, name, doc, ...)                          \
  static const ::planeslam::app::ConfigSectionRegistrar<Type> PLANESLAM_CONFIG_CONCAT( \
      planeslam_config_section_, __LINE__)(name, doc, __VA_ARGS__)
