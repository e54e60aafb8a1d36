# Installs the build at BUILD_DIR into WORK_DIR/prefix, then configures and
# builds EXAMPLES_DIR as an outside project that finds lockstep with
# find_package, and runs its program on MODEL.
function(run)
  execute_process(COMMAND ${ARGV} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "failed (${rc}): ${ARGV}\n${out}\n${err}")
  endif()
  set(run_output "${out}" PARENT_SCOPE)
endfunction()

file(REMOVE_RECURSE ${WORK_DIR})
run(${CMAKE_COMMAND} --install ${BUILD_DIR} --prefix ${WORK_DIR}/prefix)
run(${CMAKE_COMMAND} -S ${EXAMPLES_DIR} -B ${WORK_DIR}/build
    -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_COMPILER=${CXX_COMPILER} -DCMAKE_PREFIX_PATH=${WORK_DIR}/prefix)
run(${CMAKE_COMMAND} --build ${WORK_DIR}/build -j 2)
run(${WORK_DIR}/build/print_model ${MODEL})
if(NOT run_output MATCHES "mass matrix")
  message(FATAL_ERROR "print_model printed no mass matrix:\n${run_output}")
endif()
run(${WORK_DIR}/build/hold_pose ${MODEL} 64)
if(NOT run_output MATCHES "64 copies after 1 s: .* 0 faulted")
  message(FATAL_ERROR "hold_pose did not step 64 copies cleanly:\n${run_output}")
endif()
# The installed CLI finds the installed models too.
run(${WORK_DIR}/prefix/bin/lockstep info ${WORK_DIR}/prefix/share/lockstep/models/quadruped.urdf --floating-base)
message(STATUS "installed, built and ran the find_package(lockstep) consumer")
