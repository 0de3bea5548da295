# Fails when a header of the algorithm (include/tjepa/ outside sim/ and eval/, and the umbrellas
# tjepa.hpp and kernels.hpp) includes the simulator or the paper's evaluation: those are
# applications of the library (<tjepa/sim.hpp>, <tjepa/eval.hpp>), and a robot codebase that
# includes <tjepa/tjepa.hpp> gets neither. Run as a CTest test:
#   cmake -DDIR=<include/tjepa> -P check_layers.cmake
file(GLOB_RECURSE headers RELATIVE ${DIR} ${DIR}/*.hpp)
set(bad "")
set(core 0)
foreach(h IN LISTS headers)
  if(h MATCHES "^(sim|eval)/" OR h STREQUAL "sim.hpp" OR h STREQUAL "eval.hpp")
    continue()
  endif()
  math(EXPR core "${core} + 1")
  file(STRINGS ${DIR}/${h} lines REGEX "#[ \t]*include[ \t]*[<\"]tjepa/(sim|eval)[/.]")
  foreach(l IN LISTS lines)
    string(STRIP "${l}" l)
    list(APPEND bad "include/tjepa/${h}: ${l}")
  endforeach()
endforeach()
if(bad)
  list(JOIN bad "\n" text)
  message(FATAL_ERROR "headers of the algorithm include the simulator or the evaluation:\n${text}")
endif()
if(core LESS 50)
  message(FATAL_ERROR "only ${core} headers of the algorithm found under ${DIR}: wrong directory?")
endif()
message(STATUS "${core} headers of the algorithm: none includes sim/ or eval/")
