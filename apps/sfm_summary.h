#pragma once
// The SfM part of a run's JSON summary, shared by `sfm` (sfm.json) and `reconstruct`
// (reconstruct.json, which adds the surface's fields): what the SfM made of the drive, the
// frames it skipped and every warning of the run (docs/errors.md, rule 3).

#include <nlohmann/json.hpp>
#include <vector>

namespace omni {

class Drive;
struct SfmRunResult;
struct SfmOutputs;

// Keys: drive, status ("usable" / "not_usable"), sfm_outcome, outcome, mode, frames,
// frames_skipped, skipped, warnings, frames_tracked, frames_not_tracked, untracked_runs,
// keyframes, points, loop_closure(s) (one object per closure; `replay_seconds[i]` and
// `replay_keyframes[i]` add the surface's replay of closure i when given), colmap_*,
// final_bundle_adjustment, final_frame_refinement, seconds, frames_per_second, sfm_seconds and
// stage_seconds.
nlohmann::json SfmSummaryJson(const Drive& drive, const SfmRunResult& run,
                              const SfmOutputs& outputs, bool central,
                              const std::vector<double>& replay_seconds = {},
                              const std::vector<size_t>& replay_keyframes = {});

}  // namespace omni
