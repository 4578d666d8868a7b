#include "apps/cli.h"

int main(int argc, char** argv) { return omni::RunCommandLine(argc, argv); }
