# Workarounds for building a ROS 2 interface package against the PyPI ros-jazzy-* wheels with plain
# CMake (no colcon, no apt ROS). Injected right after project() by tools/build_amr_msgs.py through
# CMAKE_PROJECT_<name>_INCLUDE, so the package's own CMakeLists.txt stays a standard one.

# 1. rosidl finds its type supports through the ament index: point it at the venv prefix.
if(NOT DEFINED ENV{AMENT_PREFIX_PATH} OR "$ENV{AMENT_PREFIX_PATH}" STREQUAL "")
  list(GET CMAKE_PREFIX_PATH 0 _ros_pypi_prefix)
  set(ENV{AMENT_PREFIX_PATH} "${_ros_pypi_prefix}")
endif()

# 2. The wheels' exported targets carry the wheel builder's Python include dirs
#    (/opt/python/cpXY-cpXY/...). Replace them with this interpreter's Python and NumPy headers
#    once every find_package() of the project has run (deferred to the end of the directory).
find_package(Python3 REQUIRED COMPONENTS Interpreter Development.Module NumPy)

function(_ros_pypi_fix_include_dirs)
  get_directory_property(_targets IMPORTED_TARGETS)
  foreach(_target IN LISTS _targets)
    get_target_property(_dirs ${_target} INTERFACE_INCLUDE_DIRECTORIES)
    if(NOT _dirs)
      continue()
    endif()
    set(_kept ${_dirs})
    list(FILTER _kept EXCLUDE REGEX "^/opt/python/")
    if(NOT "${_kept}" STREQUAL "${_dirs}")
      list(APPEND _kept ${Python3_INCLUDE_DIRS} ${Python3_NumPy_INCLUDE_DIRS})
      set_target_properties(${_target} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${_kept}")
    endif()
  endforeach()
endfunction()
cmake_language(DEFER CALL _ros_pypi_fix_include_dirs)
