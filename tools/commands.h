#pragma once
// The subcommands of the meshsweep tool. Each one is a row of the table in meshsweep.cpp:
// to add a subcommand, write its run function and help text in its own file, declare them
// here and add a row to kCommands.
#include "tools/cli.h"

namespace meshsweeper::cli {

struct Command {
  const char* name;     // as typed: "meshsweep NAME ..."
  const char* summary;  // one line for "meshsweep help"
  const char* help;     // full usage text for "meshsweep help NAME" / "meshsweep NAME --help"
  // Runs the subcommand on argv[first..argc) (the arguments after NAME). Returns the exit
  // code; throws UsageError, IoError, MeshError or std::exception, which main() reports.
  int (*run)(int argc, char** argv, int first);
};

// meshsweep closest MESH POINTS [--out FILE] [--tolerance T | --k N | --within D]
extern const char kClosestHelp[];
int runClosest(int argc, char** argv, int first);

// meshsweep sample MESH N [--near F | --box F] [--seed S] [--out FILE]
extern const char kSampleHelp[];
int runSample(int argc, char** argv, int first);

// meshsweep check MESH [--voxel V] [--points N] [--band B] [--seed S] [--unsigned]
extern const char kCheckHelp[];
int runCheck(int argc, char** argv, int first);

// meshsweep hausdorff A B [--tolerance T | --relative R] [--json FILE] [--colors FILE.ply]
//                         [--threads N] [--both]
extern const char kHausdorffHelp[];
int runHausdorff(int argc, char** argv, int first);

// meshsweep info MESH [--queries N]
extern const char kInfoHelp[];
int runInfo(int argc, char** argv, int first);

// meshsweep scene NAME [--out DIR]
extern const char kSceneHelp[];
int runScene(int argc, char** argv, int first);

}  // namespace meshsweeper::cli
