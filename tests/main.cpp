// The test runner's main, and the first of two translation units that include the umbrella
// header: with tests/core/core.cpp it links into one binary, so a non-inline function defined in
// a header breaks the build.
#define DOCTEST_CONFIG_IMPLEMENT_WITH_MAIN
#include <doctest/doctest.h>

#include <tjepa/tjepa.hpp>
