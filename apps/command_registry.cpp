#include "command_registry.hpp"

namespace planeslam::app {

std::vector<CommandFactory>& CommandRegistry() {
  static std::vector<CommandFactory> registry;
  return registry;
}

}  // namespace planeslam::app
