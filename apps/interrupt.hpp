#pragma once
/// Graceful interruption of long runs: the first SIGINT/SIGTERM asks the work loop to stop after
/// the current frame (outputs for the frames done are still written); a second one exits at once,
/// removing any half-written temporary output so no partial file is left.

namespace planeslam::app {

/// Installs the SIGINT and SIGTERM handlers (idempotent).
void InstallInterruptHandlers();
/// True once a first SIGINT/SIGTERM arrived.
bool StopRequested();

}  // namespace planeslam::app
