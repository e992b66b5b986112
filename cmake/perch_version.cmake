# Run at every build (tasks/CMakeLists.txt, target perch_version): writes OUT from IN with
# PERCH_GIT_COMMIT = the short commit of SRC, "-dirty" when tracked files outside models/ and
# docs/ differ from it (an evaluation appending to a committed records file under models/ does
# not make the code dirty), but only when that changes, so a build names the code it was built
# from and a build on the same commit recompiles nothing.
execute_process(COMMAND git rev-parse --short=7 HEAD WORKING_DIRECTORY ${SRC}
                OUTPUT_VARIABLE PERCH_GIT_COMMIT OUTPUT_STRIP_TRAILING_WHITESPACE ERROR_QUIET)
if(NOT PERCH_GIT_COMMIT)
  set(PERCH_GIT_COMMIT "unknown")
else()
  execute_process(COMMAND git diff --quiet HEAD -- . ":(exclude)models" ":(exclude)docs"
                  WORKING_DIRECTORY ${SRC} RESULT_VARIABLE dirty OUTPUT_QUIET ERROR_QUIET)
  if(NOT dirty EQUAL 0)
    string(APPEND PERCH_GIT_COMMIT "-dirty")
  endif()
endif()
configure_file(${IN} ${OUT}.tmp @ONLY)
file(COPY_FILE ${OUT}.tmp ${OUT} ONLY_IF_DIFFERENT)
file(REMOVE ${OUT}.tmp)
