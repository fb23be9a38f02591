#pragma once
/// The report page's assets, embedded at build time from web/ (apps/CMakeLists.txt,
/// web/embed_report.cmake): "html" (template), "style" and "script" (the page's code bundled with
/// three.js). "script" is empty in a build made without web/node_modules.
#include <string>

namespace planeslam::app {

/// The asset `name`, or an empty string for an unknown name.
const std::string& ReportAsset(const std::string& name);

}  // namespace planeslam::app
