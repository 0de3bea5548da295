# Builds and runs a consumer project of tjepa. MODE: find_package | add_subdirectory.
set(dir ${WORK_DIR}/${MODE})
file(REMOVE_RECURSE ${dir})
function(run)
  execute_process(COMMAND ${ARGV} RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "failed (${rc}): ${ARGV}")
  endif()
endfunction()
set(cfg -G ${GENERATOR} -DCMAKE_CXX_COMPILER=${CXX} -DCMAKE_BUILD_TYPE=Release)
if(MODE STREQUAL "find_package")
  # Install from a fresh configure of the source tree into a temporary prefix.
  run(${CMAKE_COMMAND} -S ${TJEPA_SOURCE_DIR} -B ${dir}/tjepa-build ${cfg}
      -DTJEPA_BUILD_TESTS=OFF -DTJEPA_BUILD_BENCHMARKS=OFF -DTJEPA_BUILD_EXAMPLES=OFF -DTJEPA_BUILD_APPS=OFF
      -DCMAKE_INSTALL_PREFIX=${dir}/prefix)
  run(${CMAKE_COMMAND} --install ${dir}/tjepa-build)
  if(NOT EXISTS ${dir}/prefix/share/cmake/tjepa/tjepaConfigVersion.cmake)
    message(FATAL_ERROR "install did not write tjepaConfigVersion.cmake")
  endif()
  run(${CMAKE_COMMAND} -S ${TJEPA_SOURCE_DIR}/tests/package/find_package -B ${dir}/build ${cfg}
      -DCMAKE_PREFIX_PATH=${dir}/prefix)
else()
  run(${CMAKE_COMMAND} -S ${TJEPA_SOURCE_DIR}/tests/package/add_subdirectory -B ${dir}/build ${cfg}
      -DTJEPA_SOURCE_DIR=${TJEPA_SOURCE_DIR})
endif()
run(${CMAKE_COMMAND} --build ${dir}/build)
run(${dir}/build/consumer)
