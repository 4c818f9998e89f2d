# Checks that docs/ documents every option of every command, and only options that exist:
#  - every option that `iso COMMAND --help` prints (each name of a line that starts with two
#    spaces and a dash: `-o,--output TEXT`, `--no-tile-cones{false}`) must be in the first cell of
#    a row of an options table of docs/COMMAND.md;
#  - every option in the first cell of such a row must be one that `iso COMMAND --help` prints.
# An options table is a Markdown table whose header row starts with `| option |`; its rows run to
# the first line that does not start with `|`. A page may have several. Options named elsewhere on
# a page (in prose, or another command's) are not checked.
# Prints every mismatch, naming the command and the option; fails if there is one.
#
#   cmake -DISO=<path to the iso program> -DROOT=<repository root> -P tests/check_docs.cmake
cmake_minimum_required(VERSION 3.25)
if(NOT ISO OR NOT ROOT)
  message(FATAL_ERROR "usage: cmake -DISO=<iso program> -DROOT=<repository root> "
                      "-P tests/check_docs.cmake")
endif()
get_filename_component(ROOT "${ROOT}" ABSOLUTE)

set(commands convert view export bake eval info verify gen)
set(mismatches 0)
function(mismatch)
  string(JOIN "" text ${ARGN})
  message("${text}")
  math(EXPR n "${mismatches} + 1")
  set(mismatches ${n} PARENT_SCOPE)
endfunction()

# The lines of `text` as a list; characters that a CMake list would read as structure
# (semicolons, brackets, backslashes) are replaced first.
function(lines_of text out)
  string(REPLACE "\\" "/" text "${text}")
  string(REPLACE ";" "," text "${text}")
  string(REPLACE "[" "(" text "${text}")
  string(REPLACE "]" ")" text "${text}")
  string(REPLACE "\n" ";" text "${text}")
  set(${out} "${text}" PARENT_SCOPE)
endfunction()

# The option names `iso <command> --help` prints.
function(help_options command out)
  execute_process(COMMAND "${ISO}" ${command} --help
                  OUTPUT_VARIABLE help ERROR_VARIABLE error RESULT_VARIABLE status)
  if(NOT status EQUAL 0)
    message(FATAL_ERROR "iso ${command} --help failed (${status}): ${error}")
  endif()
  lines_of("${help}" lines)
  set(names "")
  foreach(line IN LISTS lines)
    if(line MATCHES "^  (-[^ ]+)")
      string(REGEX REPLACE "{.*$" "" spec "${CMAKE_MATCH_1}")
      string(REPLACE "," ";" spec "${spec}")
      list(APPEND names ${spec})
    endif()
  endforeach()
  if(NOT names)
    message(FATAL_ERROR "iso ${command} --help prints no options")
  endif()
  set(${out} "${names}" PARENT_SCOPE)
endfunction()

# The option names in the first cells of the options tables of `page`.
function(documented_options page out)
  if(NOT EXISTS "${page}")
    set(${out} "" PARENT_SCOPE)
    return()
  endif()
  file(READ "${page}" text)
  lines_of("${text}" lines)
  set(names "")
  set(inTable FALSE)
  foreach(line IN LISTS lines)
    if(line MATCHES "^\\| *option *\\|")
      set(inTable TRUE)
    elseif(NOT line MATCHES "^\\|")
      set(inTable FALSE)
    elseif(inTable AND line MATCHES "^\\|([^|]*)\\|")
      string(REGEX MATCHALL "`-[-A-Za-z0-9]+`" found "${CMAKE_MATCH_1}")
      list(TRANSFORM found REPLACE "`" "")
      list(APPEND names ${found})
    endif()
  endforeach()
  set(${out} "${names}" PARENT_SCOPE)
endfunction()

set(checked 0)
foreach(command IN LISTS commands)
  set(page "${ROOT}/docs/${command}.md")
  help_options(${command} printed)
  documented_options("${page}" documented)
  if(NOT EXISTS "${page}")
    mismatch("docs/${command}.md: missing (iso ${command} has a page of its own)")
    continue()
  endif()
  foreach(name IN LISTS printed)
    math(EXPR checked "${checked} + 1")
    if(NOT name IN_LIST documented)
      mismatch("iso ${command}: ${name}, which `iso ${command} --help` prints, is not in an "
               "options table of docs/${command}.md")
    endif()
  endforeach()
  foreach(name IN LISTS documented)
    if(NOT name IN_LIST printed)
      mismatch("iso ${command}: ${name}, in an options table of docs/${command}.md, is not an "
               "option `iso ${command} --help` prints")
    endif()
  endforeach()
endforeach()

if(mismatches GREATER 0)
  message(FATAL_ERROR "${mismatches} option(s) documented wrongly or not at all")
endif()
list(LENGTH commands ncommands)
message("docs: the ${checked} options of ${ncommands} commands are documented in docs/, "
        "and docs/ lists no other")
