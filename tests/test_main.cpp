// Catch2's own implementation, compiled here, uses std::regex; under the ASan/UBSan build GCC 12
// reports a maybe-uninitialized false positive inside libstdc++'s regex automaton (its
// std::function moves). It is third-party code: the warning is turned off for this file only.
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#define CATCH_CONFIG_MAIN
#include <catch2/catch.hpp>
