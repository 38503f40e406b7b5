#pragma once
// Stats with a standard meaning. A pass that reports one of these quantities reports it under this name, so a tool
// that drives passes it does not know (`loom bench`) reads it without knowing the pass type.
namespace loom::stat {

/// Frames in the running mean of a pass that accumulates frames (one whose parameters declare
/// ParamRole::AutoReset), counted since its last restart.
inline constexpr char kAccumulatedFrames[] = "frames";

/// 1 on a frame where a pass threw away the running mean that is its output (a reference being accumulated) and
/// started again, else 0; `loom render` warns when that happens after the first frame. A pass that blends its mean
/// into a denoised image restarts under motion by design, and does not report it.
inline constexpr char kOutputMeanRestarted[] = "outputMeanRestarted";

}  // namespace loom::stat
