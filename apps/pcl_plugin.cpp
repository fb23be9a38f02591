// Loads the PCL baselines plugin (apps/pcl/baselines.hpp) on first use and forwards OmpsDetector
// and GicpOdometry to the objects it makes.
#ifdef PLANESLAM_HAVE_PCL_BASELINES
#include <dlfcn.h>

#include <exception>
#include <filesystem>
#include <mutex>
#include <string>
#include <vector>

#include "pcl/baselines.hpp"
#include "planeslam/datasets/errors.hpp"

namespace planeslam::app::pcl_baselines {
namespace {

constexpr const char* kPluginFile = "libplaneslam_pcl.so";

/// The entry points of a loaded plugin.
struct Plugin {
  decltype(&planeslam_pcl_make_omps) make_omps = nullptr;
  decltype(&planeslam_pcl_make_gicp) make_gicp = nullptr;
};

/// Where the plugin is looked for: beside the file that holds this code (the executable, or the
/// Python module), then in the build's output folder.
std::vector<std::string> PluginCandidates() {
  std::vector<std::string> paths;
  Dl_info info{};
  if (dladdr(reinterpret_cast<void*>(&PluginCandidates), &info) != 0 && info.dli_fname) {
    std::error_code ec;
    const auto self = std::filesystem::canonical(info.dli_fname, ec);
    if (!ec) paths.push_back((self.parent_path() / kPluginFile).string());
  }
  const std::string built = std::string(PLANESLAM_PCL_PLUGIN_DIR) + "/" + kPluginFile;
  if (paths.empty() || paths.front() != built) paths.push_back(built);
  return paths;
}

Plugin LoadPlugin() {
  std::string tried;
  for (const std::string& path : PluginCandidates()) {
    if (!std::filesystem::exists(path)) {
      tried += (tried.empty() ? "" : ", ") + path;
      continue;
    }
    void* handle = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (handle == nullptr) throw IoError(path, std::string("cannot load the PCL plugin: ") + dlerror());
    const auto abi = reinterpret_cast<decltype(&planeslam_pcl_plugin_abi)>(
        dlsym(handle, "planeslam_pcl_plugin_abi"));
    Plugin plugin;
    plugin.make_omps =
        reinterpret_cast<decltype(plugin.make_omps)>(dlsym(handle, "planeslam_pcl_make_omps"));
    plugin.make_gicp =
        reinterpret_cast<decltype(plugin.make_gicp)>(dlsym(handle, "planeslam_pcl_make_gicp"));
    if (abi == nullptr || abi() != kPluginAbi || !plugin.make_omps || !plugin.make_gicp) {
      throw IoError(path, "not a PCL plugin of this planeslam build (rebuild it)");
    }
    return plugin;  // kept loaded until the process ends
  }
  throw IoError(kPluginFile, "the PCL baselines plugin was not found (looked for " + tried +
                                 "; build the target planeslam_pcl_plugin)");
}

/// The plugin, loaded once; a failure is thrown again on every use.
const Plugin& GetPlugin() {
  static std::once_flag once;
  static Plugin plugin;
  static std::exception_ptr failure;
  std::call_once(once, [] {
    try {
      plugin = LoadPlugin();
    } catch (...) {
      failure = std::current_exception();
    }
  });
  if (failure) std::rethrow_exception(failure);
  return plugin;
}

}  // namespace

OmpsDetector::OmpsDetector(OmpsConfig config)
    : config_(std::move(config)), impl_(GetPlugin().make_omps(&config_)) {}

OmpsDetector::~OmpsDetector() = default;

detection::Segmentation OmpsDetector::Detect(const datasets::OrganizedCloud& cloud) const {
  return impl_->Detect(cloud);
}

GicpOdometry::GicpOdometry(GicpConfig config) : impl_(GetPlugin().make_gicp(&config)) {}

GicpOdometry::~GicpOdometry() = default;

GicpStep GicpOdometry::Track(const datasets::OrganizedCloud& cloud) { return impl_->Track(cloud); }

void GicpOdometry::Reset() { impl_->Reset(); }

}  // namespace planeslam::app::pcl_baselines
#endif
