# SPDX-License-Identifier: MIT
# aneu_require(<find_package args...> DEBIAN <package> [<package>...])
# find_package() that, when the package is missing, stops the configure naming the Debian package to install.
macro(aneu_require name)
  cmake_parse_arguments(_ar "" "" "DEBIAN;ARGS" ${ARGN})
  find_package(${name} ${_ar_ARGS} QUIET)
  if(NOT ${name}_FOUND)
    message(FATAL_ERROR "aneuclip: required dependency '${name}' not found. "
      "Install the Debian package(s): ${_ar_DEBIAN} (scripts/install_deps.sh installs everything).")
  endif()
endmacro()
