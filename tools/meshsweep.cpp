// meshsweep: the Meshsweeper command-line tool. `meshsweep help` lists the subcommands.
//
// main() looks the subcommand up in kCommands and runs it; every error ends here as
// "meshsweep: <message>" on standard error and exit status 1 (input or output file) or
// 2 (command line). See tools/cli.h.
#include "core/mesh.h"
#include "tools/commands.h"

#include <cstdio>
#include <cstring>
#include <exception>
#include <new>
#include <string>
#include <vector>

namespace meshsweeper::cli {

namespace {

int runHelp(int argc, char** argv, int first);

// The subcommands, in the order `meshsweep help` lists them.
const Command kCommands[] = {
    {"closest", "closest points (or k closest / within-D triangles) of a mesh, as CSV",
     kClosestHelp, runClosest},
    {"sample", "generate reproducible query points near a mesh or in its bounding box",
     kSampleHelp, runSample},
    {"check", "cross-check exact distances against an OpenVDB distance grid", kCheckHelp, runCheck},
    {"hausdorff", "certified Hausdorff distance between two meshes (both directions, bounds)",
     kHausdorffHelp, runHausdorff},
    {"info", "hierarchy of a mesh: build phases, tree shape, memory per triangle and per stream",
     kInfoHelp, runInfo},
    {"scene", "run a demo scene and write its picture (PNG): hausdorff, particle, cloth, all",
     kSceneHelp, runScene},
    {"help", "show this help, or the usage of one command: meshsweep help COMMAND",
     "Usage: meshsweep help [COMMAND]\n", runHelp},
};

const Command* findCommand(const char* name) {
  for (const Command& command : kCommands) {
    if (std::strcmp(command.name, name) == 0) return &command;
  }
  return nullptr;
}

void printUsage(std::FILE* stream) {
  std::fprintf(stream,
               "meshsweep: exact point-to-triangle-mesh distance queries (Meshsweeper)\n"
               "\n"
               "Usage: meshsweep COMMAND [ARGUMENTS]\n"
               "\n"
               "Commands:\n");
  for (const Command& command : kCommands)
    std::fprintf(stream, "  %-10s %s\n", command.name, command.summary);
  std::fprintf(stream,
               "\n"
               "Run 'meshsweep help COMMAND' or 'meshsweep COMMAND --help' for its options.\n"
               "Exit status: 0 success, 1 unreadable/invalid input file or unwritable output,\n"
               "2 bad command line.\n");
}

bool isHelpFlag(const char* arg) {
  return std::strcmp(arg, "--help") == 0 || std::strcmp(arg, "-h") == 0;
}

// "help [COMMAND]"; a help flag among its words asks for help's own usage when no command is
// named ("help --help"), else is redundant ("help closest -h").
int runHelp(int argc, char** argv, int first) {
  std::vector<const char*> words;
  bool flag = false;
  for (int i = first; i < argc; ++i) {
    if (isHelpFlag(argv[i])) flag = true;
    else words.push_back(argv[i]);
  }
  if (words.empty()) {
    if (flag) std::fputs(findCommand("help")->help, stdout);
    else printUsage(stdout);
    return kExitOk;
  }
  if (words.size() > 1) throw UsageError(std::string("help: unexpected argument '") + words[1] + "'");
  const Command* command = findCommand(words[0]);
  if (!command) throw UsageError(std::string("help: unknown command '") + words[0] + "'");
  std::fputs(command->help, stdout);
  return kExitOk;
}

int dispatch(int argc, char** argv) {
  if (argc < 2) {
    printUsage(stderr);
    return kExitUsage;
  }
  if (isHelpFlag(argv[1])) return runHelp(argc, argv, 2);
  const Command* command = findCommand(argv[1]);
  if (!command)
    throw UsageError(std::string("unknown command '") + argv[1] +
                     "' (run 'meshsweep help' for the list)");
  try {
    return command->run(argc, argv, 2);
  } catch (const HelpRequested&) {  // "--help" or "-h" where an option may stand (Args)
    std::fputs(command->help, stdout);
    return kExitOk;
  }
}

}  // namespace
}  // namespace meshsweeper::cli

int main(int argc, char** argv) {
  using namespace meshsweeper::cli;
  try {
    const int status = dispatch(argc, argv);
    // Every command's report to standard output (printf or Output) must have reached it.
    if (std::fflush(stdout) != 0 || std::ferror(stdout)) throw IoError("standard output: write failed");
    return status;
  } catch (const UsageError& e) {
    std::fprintf(stderr, "meshsweep: %s\n", oneLine(e.what()).c_str());
    return kExitUsage;
  } catch (const meshsweeper::MeshError& e) {
    std::fprintf(stderr, "meshsweep: %s\n", oneLine(e.what()).c_str());
    return kExitInput;
  } catch (const IoError& e) {
    std::fprintf(stderr, "meshsweep: %s\n", oneLine(e.what()).c_str());
    return kExitInput;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "meshsweep: out of memory\n");
    return kExitInput;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "meshsweep: %s\n", oneLine(e.what()).c_str());
    return kExitInput;
  }
}
