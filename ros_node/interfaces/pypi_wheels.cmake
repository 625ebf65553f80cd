# The ROS 2 wheels on PyPI export CMake targets naming the Python and numpy include directories of the
# machine that built them (/opt/python/...); point them at this machine's. Does nothing elsewhere.
find_package(Python3 REQUIRED COMPONENTS Interpreter Development)
execute_process(COMMAND ${Python3_EXECUTABLE} -c "import numpy; print(numpy.get_include())"
                OUTPUT_VARIABLE NUMPY_INCLUDE OUTPUT_STRIP_TRAILING_WHITESPACE)
get_property(_imported DIRECTORY PROPERTY IMPORTED_TARGETS)
foreach(_t IN LISTS _imported)
  get_target_property(_dirs ${_t} INTERFACE_INCLUDE_DIRECTORIES)
  if(_dirs)
    list(TRANSFORM _dirs REPLACE "^/opt/python/[^/]+/include/python3\\.11$" "${Python3_INCLUDE_DIRS}")
    list(TRANSFORM _dirs REPLACE "^/opt/python/[^/]+/lib/python3\\.11/site-packages/numpy/_core/include$" "${NUMPY_INCLUDE}")
    set_target_properties(${_t} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${_dirs}")
  endif()
endforeach()
