# Fails when a doctest TEST_CASE name holds a comma or a semicolon: doctest's CTest discovery
# passes the name as a filter, where both split it, so such a test loses its suite label (and
# `ctest -L <area>` skips it). Run as a CTest test: cmake -DDIR=<tests dir> -P check_test_names.cmake
file(GLOB_RECURSE sources ${DIR}/*.cpp)
set(bad "")
foreach(f IN LISTS sources)
  file(STRINGS ${f} lines REGEX "TEST_CASE\\(\"[^\"]*[,;]")
  foreach(l IN LISTS lines)
    string(STRIP "${l}" l)
    list(APPEND bad "${f}: ${l}")
  endforeach()
endforeach()
if(bad)
  list(JOIN bad "\n" text)
  message(FATAL_ERROR "test names with a comma or a semicolon (use ' / ' instead):\n${text}")
endif()
list(LENGTH sources n)
message(STATUS "${n} test sources: no test name holds a comma or a semicolon")
