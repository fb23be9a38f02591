#include "interrupt.hpp"

#include <unistd.h>

#include <atomic>
#include <csignal>
#include <cstring>

#include "planeslam/datasets/atomic_file.hpp"

namespace planeslam::app {
namespace {

std::atomic<int> g_signals_received{0};

void OnSignal(int signal_number) {
  const int count = ++g_signals_received;
  if (count == 1) {
    const char msg[] =
        "\nplaneslam: interrupted: finishing the current frame and writing outputs "
        "(interrupt again to abort without outputs)\n";
    [[maybe_unused]] ssize_t n = ::write(STDERR_FILENO, msg, sizeof(msg) - 1);
    return;
  }
  datasets::RemoveActiveTempFilesFromSignalHandler();
  const char msg[] = "\nplaneslam: aborted\n";
  [[maybe_unused]] ssize_t n = ::write(STDERR_FILENO, msg, sizeof(msg) - 1);
  ::_exit(128 + signal_number);
}

}  // namespace

void InstallInterruptHandlers() {
  struct sigaction action;
  std::memset(&action, 0, sizeof(action));
  action.sa_handler = &OnSignal;
  sigemptyset(&action.sa_mask);
  ::sigaction(SIGINT, &action, nullptr);
  ::sigaction(SIGTERM, &action, nullptr);
}

bool StopRequested() { return g_signals_received.load() > 0; }

}  // namespace planeslam::app
