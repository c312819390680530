# cmake -DKINEMO_SOURCE=REPO -DWORK=DIR -DGENERATOR=G -P layout_rule_test.cmake
# Configures small projects that include the real cmake/kinemo_layout.cmake and
# checks what the configure says (tests/unit/layout/CMakeLists.txt).
file(REMOVE_RECURSE "${WORK}")
set(_failures "")

# configure(NAME BODY EXPECT_OK MUST_CONTAIN...): a project of one empty source
# whose CMakeLists.txt is BODY, configured; EXPECT_OK TRUE if it must pass.
function(configure name body expect_ok)
  set(dir "${WORK}/${name}")
  file(MAKE_DIRECTORY "${dir}")
  file(WRITE "${dir}/x.cc" "int x() { return 1; }\n")
  file(WRITE "${dir}/main.cc" "int main() { return 0; }\n")
  file(WRITE "${dir}/CMakeLists.txt"
    "cmake_minimum_required(VERSION 3.22)\nproject(${name} LANGUAGES CXX)\n"
    "include(\"${KINEMO_SOURCE}/cmake/kinemo_layout.cmake\")\n${body}\nkinemo_check_layout()\n")
  execute_process(COMMAND ${CMAKE_COMMAND} -S "${dir}" -B "${dir}/build" -G "${GENERATOR}"
                  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  set(all "${out}${err}")
  # CMake wraps long messages; compare with single spaces.
  string(REGEX REPLACE "[ \t\r\n]+" " " flat "${all}")
  if(expect_ok AND NOT rc EQUAL 0)
    set(_failures "${_failures}${name}: configure failed, want success:\n${all}\n" PARENT_SCOPE)
    return()
  endif()
  if(NOT expect_ok AND rc EQUAL 0)
    set(_failures "${_failures}${name}: configure passed, want the layout rule to fail it:\n${all}\n" PARENT_SCOPE)
    return()
  endif()
  foreach(want ${ARGN})
    string(FIND "${flat}" "${want}" at)
    if(at EQUAL -1)
      set(_failures "${_failures}${name}: output lacks '${want}':\n${all}\n" PARENT_SCOPE)
      return()
    endif()
  endforeach()
  message(STATUS "${name}: as expected")
endfunction()

# A user executable linking the harness through a library: refused, with the chain.
configure(user_links_harness [[
add_library(harness STATIC x.cc)
kinemo_layout_test_only(harness)
add_library(launcher STATIC x.cc)
target_link_libraries(launcher PUBLIC harness)
add_executable(tool main.cc)
target_link_libraries(tool PRIVATE launcher)
kinemo_layout_user_executable(tool)
]] FALSE
  "user executable tool links the test harness harness, which is for tests only"
  "link kinemo_process to start child processes"
  "link chain: tool -> launcher -> harness")

# A test linking the harness and a user executable linking the launcher alone: fine.
configure(test_links_harness [[
add_library(harness STATIC x.cc)
kinemo_layout_test_only(harness)
add_library(launcher STATIC x.cc)
target_link_libraries(harness PUBLIC launcher)
add_executable(a_test main.cc)
target_link_libraries(a_test PRIVATE harness)
add_executable(tool main.cc)
target_link_libraries(tool PRIVATE launcher)
kinemo_layout_user_executable(tool)
]] TRUE
  "layout rule holds" "1 user executables link no test harness")

# A core linking an adapter through another library: refused, with the chain.
configure(core_links_adapter [[
add_library(adapter STATIC x.cc)
kinemo_layout_role(adapter adapter)
add_library(middle STATIC x.cc)
target_link_libraries(middle PUBLIC adapter)
add_library(engine STATIC x.cc)
target_link_libraries(engine PUBLIC middle)
kinemo_layout_role(core engine)
]] FALSE
  "core target engine links adapter target adapter"
  "link chain: engine -> middle -> adapter")

if(_failures)
  message(FATAL_ERROR "${_failures}")
endif()
