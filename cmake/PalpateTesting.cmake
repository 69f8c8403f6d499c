# palpate_isolated_test(NAME <name> COMMAND <program> [<args>...] [TIMEOUT <s>])
#
# A test that starts DDS participants runs in a private network namespace
# whose only interface is loopback, whoever starts CTest: `unshare --net`,
# then `ip link set lo up`. No DDS traffic can reach a real interface.
find_program(UNSHARE unshare REQUIRED)
find_program(IP ip PATHS /usr/sbin /sbin REQUIRED)

function(palpate_isolated_test)
  cmake_parse_arguments(ARG "" "NAME;TIMEOUT" "COMMAND" ${ARGN})
  add_test(NAME ${ARG_NAME}
    COMMAND ${UNSHARE} --net -- sh -c "${IP} link set lo up && exec \"$0\" \"$@\"" ${ARG_COMMAND})
  if(ARG_TIMEOUT)
    set_tests_properties(${ARG_NAME} PROPERTIES TIMEOUT ${ARG_TIMEOUT})
  endif()
endfunction()
