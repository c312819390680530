# The layout rule (docs/DEVELOPING.md#layout): every service is a core library
# (the engine: no gRPC headers, no gRPC link), its gRPC adapter (thin: parse,
# call the core, map the status) and main.cc. Libraries say which they are
# (kinemo_library(... CORE ...) / kinemo_library(... ADAPTER ...), or
# kinemo_layout_role() for targets made otherwise), and kinemo_check_layout(),
# called once at the end of the top-level CMakeLists.txt when every target
# exists, fails the configure when a core
#   - links an adapter target, directly or through other targets;
#   - links gRPC::grpc++ (or another gRPC::grpc++* library);
#   - includes a gRPC header (<grpcpp/...>, <grpc/...>, *.grpc.pb.h) in its
#     sources or in the project headers they include, followed transitively.
# kinemo_proto (the generated code) holds the messages the cores use and the
# service stubs, and links gRPC::grpc++ for the stubs: the link walk does not
# look through it; the include scan keeps the cores off the stubs' headers.
#
# It also fails the configure when a user executable (every
# kinemo_executable() outside tests/: kinemo, kinemo-bench, the services,
# the tools) links a test-only target (kinemo_layout_test_only(): the
# integration-test harness kinemo_testing), directly or through other targets.

# kinemo_layout_role(core|adapter TARGET...)
function(kinemo_layout_role role)
  if(NOT role MATCHES "^(core|adapter)$")
    message(FATAL_ERROR "kinemo_layout_role: the role is core or adapter, not '${role}'")
  endif()
  foreach(target ${ARGN})
    set_property(TARGET ${target} PROPERTY KINEMO_LAYOUT_ROLE ${role})
    set_property(GLOBAL APPEND PROPERTY KINEMO_LAYOUT_TARGETS ${target})
  endforeach()
endfunction()

# kinemo_layout_test_only(TARGET...): code for tests only (the harness).
function(kinemo_layout_test_only)
  foreach(target ${ARGN})
    set_property(TARGET ${target} PROPERTY KINEMO_LAYOUT_TEST_ONLY TRUE)
  endforeach()
endfunction()

# kinemo_layout_user_executable(TARGET...): an executable users run (called
# by kinemo_executable() for every executable outside tests/).
function(kinemo_layout_user_executable)
  set_property(GLOBAL APPEND PROPERTY KINEMO_LAYOUT_EXECUTABLES ${ARGN})
endfunction()

# The targets a target links itself (all of them for a library we compile,
# the interface for an interface library), generator expressions but
# $<LINK_ONLY:x> left out.
function(_kinemo_layout_links target out)
  get_target_property(_type ${target} TYPE)
  set(_links "")
  if(NOT _type STREQUAL "INTERFACE_LIBRARY")
    get_target_property(_l ${target} LINK_LIBRARIES)
    if(_l)
      list(APPEND _links ${_l})
    endif()
  endif()
  get_target_property(_l ${target} INTERFACE_LINK_LIBRARIES)
  if(_l)
    list(APPEND _links ${_l})
  endif()
  set(_result "")
  foreach(_link ${_links})
    if(_link MATCHES "^\\$<LINK_ONLY:([^$<>]+)>$")
      set(_link "${CMAKE_MATCH_1}")
    elseif(_link MATCHES "\\$<")
      continue()
    endif()
    if(TARGET ${_link})
      get_target_property(_aliased ${_link} ALIASED_TARGET)
      if(_aliased)
        set(_link ${_aliased})
      endif()
    endif()
    list(APPEND _result ${_link})
  endforeach()
  list(REMOVE_DUPLICATES _result)
  set(${out} ${_result} PARENT_SCOPE)
endfunction()

# Depth first over the link graph of `root`, each reached target with its
# chain ("root -> a -> b"). A target `stop` judges (a function setting its
# second argument to TRUE) is reported but not expanded: an offending link
# is named once, not everything behind it. Imported targets and kinemo_proto
# are reported and not expanded; link items that are not targets are
# skipped. Sets `<out>` to the reached targets and `<out>_CHAIN_<id>` (id =
# the target made a C identifier) to their chains in the caller's scope.
function(_kinemo_layout_walk root stop out)
  set(_seen ${root})
  set(_reached "")
  _kinemo_layout_links(${root} _stack)
  foreach(_l ${_stack})
    string(MAKE_C_IDENTIFIER "${_l}" _id)
    set(_chain_${_id} "${root} -> ${_l}")
  endforeach()
  while(_stack)
    list(POP_FRONT _stack _t)
    if(_t IN_LIST _seen OR NOT TARGET ${_t})
      continue()
    endif()
    list(APPEND _seen ${_t})
    list(APPEND _reached ${_t})
    string(MAKE_C_IDENTIFIER "${_t}" _id)
    set(_chain "${_chain_${_id}}")
    set(${out}_CHAIN_${_id} "${_chain}" PARENT_SCOPE)
    cmake_language(CALL ${stop} ${_t} _stop)
    get_target_property(_imported ${_t} IMPORTED)
    if(_stop OR _imported OR _t STREQUAL "kinemo_proto")
      continue()
    endif()
    _kinemo_layout_links(${_t} _next)
    foreach(_n ${_next})
      string(MAKE_C_IDENTIFIER "${_n}" _nid)
      if(NOT _n IN_LIST _seen AND NOT DEFINED _chain_${_nid})
        set(_chain_${_nid} "${_chain} -> ${_n}")
      endif()
    endforeach()
    list(PREPEND _stack ${_next})
  endwhile()
  set(${out} ${_reached} PARENT_SCOPE)
endfunction()

# What a core may not link: grpc++ and adapter targets.
function(_kinemo_layout_core_stop t out)
  set(_r FALSE)
  if(t MATCHES "^gRPC::grpc\\+\\+")
    set(_r TRUE)
  else()
    get_target_property(_role ${t} KINEMO_LAYOUT_ROLE)
    if(_role STREQUAL "adapter")
      set(_r TRUE)
    endif()
  endif()
  set(${out} ${_r} PARENT_SCOPE)
endfunction()

# What a user executable may not link: test-only targets.
function(_kinemo_layout_user_stop t out)
  get_target_property(_test_only ${t} KINEMO_LAYOUT_TEST_ONLY)
  if(_test_only)
    set(${out} TRUE PARENT_SCOPE)
  else()
    set(${out} FALSE PARENT_SCOPE)
  endif()
endfunction()

function(kinemo_check_layout)
  get_property(_targets GLOBAL PROPERTY KINEMO_LAYOUT_TARGETS)
  set(_errors "")
  set(_cores 0)
  set(_files 0)
  foreach(_core ${_targets})
    get_target_property(_role ${_core} KINEMO_LAYOUT_ROLE)
    if(NOT _role STREQUAL "core")
      continue()
    endif()
    math(EXPR _cores "${_cores} + 1")
    # Links: no grpc++ and no adapter in the core's link graph.
    _kinemo_layout_walk(${_core} _kinemo_layout_core_stop _reach)
    foreach(_t ${_reach})
      string(MAKE_C_IDENTIFIER "${_t}" _id)
      set(_chain "${_reach_CHAIN_${_id}}")
      if(_t MATCHES "^gRPC::grpc\\+\\+")
        string(APPEND _errors "core target ${_core} links ${_t} (docs/DEVELOPING.md#layout)\n  link chain: ${_chain}\n")
      else()
        get_target_property(_r ${_t} KINEMO_LAYOUT_ROLE)
        if(_r STREQUAL "adapter")
          string(APPEND _errors "core target ${_core} links adapter target ${_t} (docs/DEVELOPING.md#layout)\n  link chain: ${_chain}\n")
        endif()
      endif()
    endforeach()

    # Includes: the core's own sources, then every project header they
    # include ("common/...", "services/..."), transitively.
    get_target_property(_dir ${_core} SOURCE_DIR)
    get_target_property(_sources ${_core} SOURCES)
    set(_queue "")
    if(_sources)
      foreach(_s ${_sources})
        if(NOT IS_ABSOLUTE "${_s}")
          set(_s "${_dir}/${_s}")
        endif()
        if(_s MATCHES "\\.(cc|cpp|h|hpp)$" AND EXISTS "${_s}")
          list(APPEND _queue "${_s}")
          file(RELATIVE_PATH _rel "${PROJECT_SOURCE_DIR}" "${_s}")
          string(MAKE_C_IDENTIFIER "${_rel}" _id)
          set(_from_${_id} "")
        endif()
      endforeach()
    endif()
    set(_visited "")
    while(_queue)
      list(POP_FRONT _queue _f)
      if(_f IN_LIST _visited)
        continue()
      endif()
      list(APPEND _visited "${_f}")
      file(RELATIVE_PATH _frel "${PROJECT_SOURCE_DIR}" "${_f}")
      # Each file is read once per configure, whichever core reaches it.
      string(MAKE_C_IDENTIFIER "${_frel}" _key)
      set(_from "${_from_${_key}}")
      get_property(_known GLOBAL PROPERTY KINEMO_LAYOUT_INCLUDES_${_key} SET)
      if(NOT _known)
        math(EXPR _files "${_files} + 1")
        file(STRINGS "${_f}" _lines REGEX "^[ \t]*#[ \t]*include[ \t]*[<\"]")
        set(_includes "")
        foreach(_line ${_lines})
          if(_line MATCHES "#[ \t]*include[ \t]*([<\"][^>\"]+[>\"])")
            list(APPEND _includes "${CMAKE_MATCH_1}")
          endif()
        endforeach()
        set_property(GLOBAL PROPERTY KINEMO_LAYOUT_INCLUDES_${_key} "${_includes}")
      endif()
      get_property(_includes GLOBAL PROPERTY KINEMO_LAYOUT_INCLUDES_${_key})
      foreach(_inc ${_includes})
        string(REGEX REPLACE "^[<\"](.*)[>\"]$" "\\1" _path "${_inc}")
        if(_path MATCHES "^(grpcpp|grpc|grpc\\+\\+)/" OR _path MATCHES "\\.grpc\\.pb\\.h$")
          set(_via "")
          if(_from)
            set(_via ", included through ${_from}")
          endif()
          string(APPEND _errors "core target ${_core} includes the gRPC header ${_inc} in ${_frel}${_via} (docs/DEVELOPING.md#layout)\n")
        elseif(_inc MATCHES "^\"" AND EXISTS "${PROJECT_SOURCE_DIR}/${_path}"
               AND NOT IS_DIRECTORY "${PROJECT_SOURCE_DIR}/${_path}")
          string(MAKE_C_IDENTIFIER "${_path}" _pid)
          if(NOT DEFINED _from_${_pid})
            if(_from)
              set(_from_${_pid} "${_frel} <- ${_from}")
            else()
              set(_from_${_pid} "${_frel}")
            endif()
          endif()
          list(APPEND _queue "${PROJECT_SOURCE_DIR}/${_path}")
        endif()
      endforeach()
    endwhile()
    foreach(_f ${_visited} ${_queue})
      file(RELATIVE_PATH _frel "${PROJECT_SOURCE_DIR}" "${_f}")
      string(MAKE_C_IDENTIFIER "${_frel}" _id)
      unset(_from_${_id})
    endforeach()
  endforeach()
  # User executables: no test-only target in their link graph.
  get_property(_executables GLOBAL PROPERTY KINEMO_LAYOUT_EXECUTABLES)
  set(_users 0)
  foreach(_exe ${_executables})
    math(EXPR _users "${_users} + 1")
    _kinemo_layout_walk(${_exe} _kinemo_layout_user_stop _reach)
    foreach(_t ${_reach})
      get_target_property(_test_only ${_t} KINEMO_LAYOUT_TEST_ONLY)
      if(_test_only)
        string(MAKE_C_IDENTIFIER "${_t}" _id)
        string(APPEND _errors "user executable ${_exe} links the test harness ${_t}, which is for tests only; "
                              "link kinemo_process to start child processes (docs/DEVELOPING.md#layout)\n"
                              "  link chain: ${_reach_CHAIN_${_id}}\n")
      endif()
    endforeach()
  endforeach()

  if(_errors)
    message(FATAL_ERROR "kinemo layout rule broken:\n${_errors}")
  endif()
  message(STATUS "kinemo: layout rule holds (${_cores} core targets; ${_files} sources and headers read; "
                 "${_users} user executables link no test harness)")
endfunction()
