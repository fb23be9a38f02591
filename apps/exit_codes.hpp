#pragma once
/// The process exit codes of planeslam, one meaning each (documented in `planeslam run --help`).

namespace planeslam::app {

inline constexpr int kExitSuccess = 0;
/// Bad input, bad configuration or an unwritable output: one line on stderr, no partial output.
inline constexpr int kExitError = 2;
inline constexpr int kExitOutOfMemory = 3;
/// A bug inside planeslam (a failed precondition).
inline constexpr int kExitInternalError = 4;
/// `run` completed, leaving out frames it could not read (run.on_bad_frame: skip); summary.json
/// and frames.csv name them.
inline constexpr int kExitSkippedFrames = 5;
/// `run` ended at a frame it could not read (run.on_bad_frame: stop); the outputs cover the frames
/// before it.
inline constexpr int kExitStoppedAtBadFrame = 6;
/// Interrupted by SIGINT/SIGTERM; the outputs cover the frames done.
inline constexpr int kExitInterrupted = 130;

}  // namespace planeslam::app
