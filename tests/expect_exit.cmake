# Runs COMMAND (arguments separated by "|") and checks its exit code against
# EXPECT_RC and its stdout/stderr against the regexes EXPECT_OUT/EXPECT_ERR
# (empty: not checked; matched with newlines folded to spaces).
# With WORK_DIR, COMMAND runs there, in a folder emptied first, and
# EXPECT_ABSENT names a file that must not be there afterwards.
#   cmake -DCOMMAND="prog|arg|..." -DEXPECT_RC=2 -DEXPECT_OUT=re -DEXPECT_ERR=re -P expect_exit.cmake
string(REPLACE "|" ";" _command "${COMMAND}")
set(_work_dir_args "")
if(WORK_DIR)
  file(REMOVE_RECURSE "${WORK_DIR}")
  file(MAKE_DIRECTORY "${WORK_DIR}")
  set(_work_dir_args WORKING_DIRECTORY "${WORK_DIR}")
endif()
execute_process(COMMAND ${_command} ${_work_dir_args} RESULT_VARIABLE _rc OUTPUT_VARIABLE _out ERROR_VARIABLE _err)
string(REPLACE "\n" " " _out_line "${_out}")
string(REPLACE "\n" " " _err_line "${_err}")
set(_failures "")
if(NOT "${_rc}" STREQUAL "${EXPECT_RC}")
  string(APPEND _failures "exit code ${_rc}, expected ${EXPECT_RC}\n")
endif()
if(NOT "${EXPECT_OUT}" STREQUAL "" AND NOT _out_line MATCHES "${EXPECT_OUT}")
  string(APPEND _failures "stdout does not match: ${EXPECT_OUT}\n")
endif()
if(NOT "${EXPECT_ERR}" STREQUAL "" AND NOT _err_line MATCHES "${EXPECT_ERR}")
  string(APPEND _failures "stderr does not match: ${EXPECT_ERR}\n")
endif()
if(WORK_DIR AND EXPECT_ABSENT AND EXISTS "${WORK_DIR}/${EXPECT_ABSENT}")
  string(APPEND _failures "${EXPECT_ABSENT} was written in the working directory ${WORK_DIR}\n")
endif()
if(_failures)
  string(SUBSTRING "${_out}" 0 4000 _out_head)
  message(FATAL_ERROR "${_command}\n${_failures}--- stdout (head)\n${_out_head}\n--- stderr\n${_err}")
endif()
