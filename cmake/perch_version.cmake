# Run at every build (tasks/CMakeLists.txt, target perch_version): writes OUT from IN with
# PERCH_GIT_COMMIT = `git describe --always --dirty` of SRC, but only when that changes, so a
# build names the commit it was built from (with -dirty for uncommitted changes) and a build on
# the same commit recompiles nothing.
execute_process(COMMAND git describe --always --dirty --abbrev=7 WORKING_DIRECTORY ${SRC}
                OUTPUT_VARIABLE PERCH_GIT_COMMIT OUTPUT_STRIP_TRAILING_WHITESPACE ERROR_QUIET)
if(NOT PERCH_GIT_COMMIT)
  set(PERCH_GIT_COMMIT "unknown")
endif()
configure_file(${IN} ${OUT}.tmp @ONLY)
file(COPY_FILE ${OUT}.tmp ${OUT} ONLY_IF_DIFFERENT)
file(REMOVE ${OUT}.tmp)
