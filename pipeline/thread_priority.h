#pragma once
// The priority of the pipeline's helper threads (the surface thread, the image prefetcher):
// they run nicer than the SfM thread, which sets the pace, so that on a machine with fewer cores
// than busy threads the SfM gets a core first.

namespace omni {

// Makes the calling thread `increment` nicer than it is (Linux: niceness is per thread), up to
// 19; `what` names the thread in the debug line written when the system refuses (the run goes
// on at the same priority). Nothing elsewhere, or for an increment of 0 or less.
void LowerThisThreadPriority(int increment, const char* what);

}  // namespace omni
