# Runs a command that must fail and checks both its exit status and its output, for CTest: with
# PASS_REGULAR_EXPRESSION alone CTest ignores the exit status, so a regression to exit 0 would pass.
# Usage: cmake -P expect.cmake -- EXIT REGEX COMMAND [ARG...]
#   EXIT   the expected exit status, or "nonzero" for any failure status (a crash is no failure status)
#   REGEX  what stdout and stderr together must match (CMake regex, as PASS_REGULAR_EXPRESSION)

# The arguments after "--": EXIT, REGEX, then the command, one list element per argument (a ";"
# inside one, as in sh -c "a; b", escaped: list() commands would undo that, so none is used).
set(separator -1)
math(EXPR last "${CMAKE_ARGC} - 1")
foreach(i RANGE ${last})
  if(CMAKE_ARGV${i} STREQUAL "--")
    set(separator ${i})
    break()
  endif()
endforeach()
math(EXPR first_command "${separator} + 3")
if(separator LESS 0 OR first_command GREATER last)
  message(FATAL_ERROR "expect.cmake: usage: cmake -P expect.cmake -- EXIT REGEX COMMAND [ARG...]")
endif()
math(EXPR exit_index "${separator} + 1")
math(EXPR regex_index "${separator} + 2")
set(expected_exit "${CMAKE_ARGV${exit_index}}")
set(expected_output "${CMAKE_ARGV${regex_index}}")
set(command "")
foreach(i RANGE ${first_command} ${last})
  string(REPLACE ";" "\\;" arg "${CMAKE_ARGV${i}}")
  string(APPEND command "${arg};")
endforeach()

# Run it, stdout and stderr merged in the order written, and show what it said.
execute_process(COMMAND ${command} RESULT_VARIABLE status OUTPUT_VARIABLE output ERROR_VARIABLE output)
message("${output}")
message("exit status: ${status}")

# The exit status: a number, and the expected one.
if(NOT status MATCHES "^[0-9]+$")
  message(FATAL_ERROR "expect.cmake: the command did not exit normally (${status}); expected exit status ${expected_exit}")
elseif(expected_exit STREQUAL "nonzero")
  if(status EQUAL 0)
    message(FATAL_ERROR "expect.cmake: the command exited with 0; expected a failure status")
  endif()
elseif(NOT status EQUAL expected_exit)
  message(FATAL_ERROR "expect.cmake: the command exited with ${status}; expected ${expected_exit}")
endif()
# The output.
if(NOT output MATCHES "${expected_output}")
  message(FATAL_ERROR "expect.cmake: the output does not match the expected regex: ${expected_output}")
endif()
