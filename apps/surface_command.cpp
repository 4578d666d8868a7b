#include "apps/commands.h"

namespace omni {

// Not built yet: the subcommand is absent until its issue lands.
void RegisterSurfaceCommand(CLI::App& /*app*/, const GlobalOptions& /*global*/) {}

}  // namespace omni
