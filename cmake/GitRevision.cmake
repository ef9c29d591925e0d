# SPDX-License-Identifier: MIT
# Generates ${CMAKE_BINARY_DIR}/generated/aneu_build_info.cpp at *build* time, so the git revision recorded
# in every output file is the one that was built, not the one that was configured. The file is only
# rewritten when its content changes, so an unchanged revision triggers no rebuild.
set(ANEU_BUILD_INFO_CPP "${CMAKE_BINARY_DIR}/generated/aneu_build_info.cpp")
add_custom_target(aneu_build_info_gen
  COMMAND ${CMAKE_COMMAND} -DSRC=${CMAKE_SOURCE_DIR} -DOUT=${ANEU_BUILD_INFO_CPP}
          -DVERSION=${PROJECT_VERSION} -P ${CMAKE_SOURCE_DIR}/cmake/WriteBuildInfo.cmake
  BYPRODUCTS ${ANEU_BUILD_INFO_CPP}
  COMMENT "aneuclip build info (git revision)")
