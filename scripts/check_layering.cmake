# The layering of the libraries: which project folders each folder's files may include.
# Usage: cmake -DROOT=<source tree> -P scripts/check_layering.cmake
# Scans every .h, .cpp and .in file under each folder of the table below (a folder that does not
# exist yet is skipped) for `#include "X/..."` with X a folder of the table, and fails listing
# every include the table does not allow as `file:line: <folder> may not include X/...`.
# docs/design.md ("Libraries and layers") draws the table; ctest runs this as layering_tree.

cmake_minimum_required(VERSION 3.22)

# ---- The allowed arrows: folder -> the folders it may include ----------------------------------
set(layer_calib    calib)                             # omni_calib, the base
set(layer_sfm      calib sfm)                         # omni_sfm
set(layer_surface  calib surface)                     # omni_surface (sfm's sibling)
set(layer_raycast  calib raycast)                     # omni_raycast
set(layer_eval     calib raycast surface eval)        # omni_eval
set(layer_synth    calib raycast synth)               # omni_synth
set(layer_pipeline calib sfm surface raycast pipeline)  # omni_pipeline, the controllers
set(layer_export   calib export)                      # omni_export: glTF, OBJ, the web viewer's folder
set(layer_apps     calib sfm surface raycast eval synth pipeline export apps)  # the command line
# -------------------------------------------------------------------------------------------------

set(folders calib sfm surface raycast eval synth pipeline export apps)

if(NOT DEFINED ROOT OR ROOT STREQUAL "")
  message(FATAL_ERROR "check_layering: give the source tree: cmake -DROOT=<tree> -P ${CMAKE_CURRENT_LIST_FILE}")
endif()
get_filename_component(root "${ROOT}" ABSOLUTE)
if(NOT IS_DIRECTORY "${root}")
  message(FATAL_ERROR "check_layering: ROOT ${root} is not a folder")
endif()

set(num_files 0)
set(num_includes 0)
set(present "")
set(absent "")
set(offences "")
foreach(folder IN LISTS folders)
  if(NOT IS_DIRECTORY "${root}/${folder}")
    list(APPEND absent ${folder})
    continue()
  endif()
  list(APPEND present ${folder})
  file(GLOB_RECURSE files RELATIVE "${root}" LIST_DIRECTORIES false
       "${root}/${folder}/*.h" "${root}/${folder}/*.cpp" "${root}/${folder}/*.in")
  list(SORT files)
  foreach(file IN LISTS files)
    math(EXPR num_files "${num_files} + 1")
    file(READ "${root}/${file}" text)
    # One list element per line: characters that CMake lists treat specially are masked first.
    string(REPLACE "\\" "<bs>" text "${text}")
    string(REPLACE ";" "<sc>" text "${text}")
    string(REPLACE "[" "<lb>" text "${text}")
    string(REPLACE "]" "<rb>" text "${text}")
    string(REPLACE "\n" ";" lines "${text}")
    set(line_number 0)
    foreach(line IN LISTS lines)
      math(EXPR line_number "${line_number} + 1")
      if(NOT line MATCHES "^[ \t]*#[ \t]*include[ \t]*\"([^\"/]+)/([^\"]*)\"")
        continue()
      endif()
      set(target "${CMAKE_MATCH_1}")
      set(included "${CMAKE_MATCH_1}/${CMAKE_MATCH_2}")
      if(NOT target IN_LIST folders)
        continue()  # not a project folder (a third-party header in quotes)
      endif()
      math(EXPR num_includes "${num_includes} + 1")
      if(NOT target IN_LIST layer_${folder})
        list(APPEND offences "${file}:${line_number}: ${folder} may not include ${included}")
      endif()
    endforeach()
  endforeach()
endforeach()

if(NOT present)
  message(FATAL_ERROR "check_layering: no library folder (${folders}) under ${root}")
endif()
list(LENGTH offences num_offences)
if(num_offences GREATER 0)
  foreach(offence IN LISTS offences)
    message(NOTICE "${offence}")  # verbatim, one line each, as a compiler's file:line: messages
  endforeach()
  message(FATAL_ERROR "check_layering: ${num_offences} include(s) above break the layering "
                      "(the table at the top of scripts/check_layering.cmake)")
endif()
list(JOIN present " " present_text)
if(absent)
  list(JOIN absent " " absent_text)
  set(absent_text ", absent: ${absent_text}")
endif()
message(STATUS "check_layering: OK, ${num_files} files scanned, ${num_includes} project includes "
               "checked (folders ${present_text}${absent_text})")
