# Runs scripts/check_layering.cmake on a tree that breaks the layering and checks that it fails
# (a non-zero exit) naming exactly the expected offending lines.
# Usage: cmake -DSCRIPT=<check_layering.cmake> -DROOT=<tree> -DEXPECTED=<line>[;<line>...]
#              -P tests/check_layering_fails.cmake
# Prints "layering check failed as expected: <line>" for each expected line on success (the ctest
# test matches that); anything else ends in FATAL_ERROR.
cmake_minimum_required(VERSION 3.22)

execute_process(COMMAND "${CMAKE_COMMAND}" "-DROOT=${ROOT}" -P "${SCRIPT}"
                RESULT_VARIABLE result OUTPUT_VARIABLE out ERROR_VARIABLE err)
set(output "${out}${err}")
if(result EQUAL 0)
  message(FATAL_ERROR "the layering check passed on ${ROOT}, expected it to fail:\n${output}")
endif()
string(REGEX MATCHALL "[^\n]*: [a-z]+ may not include [^\n]*" reported "${output}")
list(LENGTH reported num_reported)
list(LENGTH EXPECTED num_expected)
if(NOT num_reported EQUAL num_expected)
  message(FATAL_ERROR "expected ${num_expected} offending line(s), got ${num_reported}:\n${output}")
endif()
foreach(line IN LISTS EXPECTED)
  if(NOT line IN_LIST reported)
    message(FATAL_ERROR "expected the offending line \"${line}\", got:\n${output}")
  endif()
endforeach()
foreach(line IN LISTS EXPECTED)
  message(STATUS "layering check failed as expected: ${line}")
endforeach()
