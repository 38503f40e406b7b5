#pragma once
// Stats with a standard meaning. A pass that reports one of these quantities reports it under this name, so a tool
// that drives passes it does not know (`loom bench`) reads it without knowing the pass type.
namespace loom::stat {

/// Frames in the running mean of a pass that accumulates frames (one whose parameters declare
/// ParamRole::AutoReset), counted since its last restart.
inline constexpr char kAccumulatedFrames[] = "frames";

}  // namespace loom::stat
