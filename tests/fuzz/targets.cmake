# The libFuzzer targets: NAME -> tests/fuzz/NAME.cc, seeds in tests/fuzz/corpus/NAME/.
# LIBS are the idms libraries each links. Shared by the clang build and the CTest runner.
set(IDMS_FUZZ_TARGETS fem_fuzz plg_fuzz obj_fuzz)
set(IDMS_FUZZ_LIBS_fem_fuzz idms_sim)
set(IDMS_FUZZ_LIBS_plg_fuzz idms_sim)
set(IDMS_FUZZ_LIBS_obj_fuzz idms_sim)
list(APPEND IDMS_FUZZ_TARGETS envelope_fuzz)
set(IDMS_FUZZ_LIBS_envelope_fuzz idms_protocol)
list(APPEND IDMS_FUZZ_TARGETS mcap_fuzz)
set(IDMS_FUZZ_LIBS_mcap_fuzz idms_protocol)
# Seconds each target runs inside the test suite (a longer run: scripts/fuzz.sh).
set(IDMS_FUZZ_SECONDS 20)
# The server's request path (Beast's parser, admission, handlers, multipart and JSON bodies).
list(APPEND IDMS_FUZZ_TARGETS http_fuzz)
set(IDMS_FUZZ_LIBS_http_fuzz idms_server_api)
# A WebSocket's first frames on /ws/agent and /ws/session/{id} (the sessions' endpoints).
list(APPEND IDMS_FUZZ_TARGETS ws_fuzz)
set(IDMS_FUZZ_LIBS_ws_fuzz idms_server)
# A replay's controls on /ws/replay/{id} (play, pause, seek, speed) against a recorded session.
list(APPEND IDMS_FUZZ_TARGETS replay_fuzz)
set(IDMS_FUZZ_LIBS_replay_fuzz idms_server)
# idms-render's and the render endpoints' parameters (size, camera, seconds).
list(APPEND IDMS_FUZZ_TARGETS render_params_fuzz)
set(IDMS_FUZZ_LIBS_render_params_fuzz idms_render_params)
# The tools' --server URLs (idms_cli: idms-agent, idms-render).
list(APPEND IDMS_FUZZ_TARGETS cli_fuzz)
set(IDMS_FUZZ_LIBS_cli_fuzz idms_cli)
# What a server takes from the bus between servers (relayed frames, state answers, relayed
# viewers' notes and commands).
list(APPEND IDMS_FUZZ_TARGETS relay_fuzz)
set(IDMS_FUZZ_LIBS_relay_fuzz idms_server)
# What the S3 client reads: a store's XML replies (listings, errors) and s3:// URLs.
list(APPEND IDMS_FUZZ_TARGETS s3_parse_fuzz)
set(IDMS_FUZZ_LIBS_s3_parse_fuzz idms_server_api)
# The command lines' tool, friction and drag specs (idms-sim run --tool/--script drag:, idms-agent
# --friction/--device scripted:drag,...).
list(APPEND IDMS_FUZZ_TARGETS spec_fuzz)
set(IDMS_FUZZ_LIBS_spec_fuzz idms_sim)
# The agent's UDP bridge: a driver's datagrams (positions, version 1 and 2 with an orientation).
list(APPEND IDMS_FUZZ_TARGETS udp_fuzz)
set(IDMS_FUZZ_LIBS_udp_fuzz idms_udp_bridge)
