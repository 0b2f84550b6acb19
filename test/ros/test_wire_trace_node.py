"""The node's wire trace: ``wire_trace`` in the parameters file, read back with tshark."""

from drive_bridge.sim.devices import make_sim_server
from ros_helpers import RosClient, start_node, stop_node, write_params
from trace_helpers import needs_tshark, outcomes, tshark_fields


@needs_tshark
def test_the_node_traces_its_line_to_the_file_the_parameter_names(tmp_path):
    line = make_sim_server({20: 'mcd500'})
    line.open_pty()
    line.start()
    trace = tmp_path / 'line.pcapng'
    params = write_params(tmp_path / 'trace.yaml',
                          {'port': line.pty_path, 'parity': 'N', 'timeout': 0.5,
                           'wire_trace': str(trace)},
                          {'starter': {'family': 'mcd', 'model': 'mcd500', 'address': 20,
                                       'poll_rate': 10.0}})
    process = start_node(params)
    client = RosClient(['starter'])
    try:
        assert client.wait_state('starter', 'ready', 15.0)
        client.values('starter', 'motor_current').clear()
        assert client.spin_until(lambda: len(client.values('starter', 'motor_current')) >= 2)
    finally:
        client.close()
        code, output = stop_node(process)
        line.stop()
    assert code == 0, output
    rows = tshark_fields(trace, 'frame.p2p_dir', 'mbrtu.unit_id', 'modbus.func_code',
                         'frame.comment')
    assert len(rows) >= 4
    assert {row[0] for row in rows} == {'0', '1'}  # both ways
    assert {row[1] for row in rows} == {'20'}
    assert rows[0][0] == '0' and rows[1][0] == '1'  # a request, then its answer
    assert outcomes(rows).count('ok') >= 4


def test_a_trace_that_cannot_be_written_is_one_logged_line_and_the_bus_goes_on(tmp_path):
    line = make_sim_server({20: 'mcd500'})
    line.open_pty()
    line.start()
    trace = tmp_path / 'missing' / 'line.txt'
    params = write_params(tmp_path / 'trace.yaml',
                          {'port': line.pty_path, 'parity': 'N', 'timeout': 0.5,
                           'wire_trace': str(trace)},
                          {'starter': {'family': 'mcd', 'model': 'mcd500', 'address': 20,
                                       'poll_rate': 10.0}})
    process = start_node(params)
    client = RosClient(['starter'])
    try:
        assert client.wait_state('starter', 'ready', 15.0)
        client.values('starter', 'motor_current').clear()
        assert client.spin_until(lambda: len(client.values('starter', 'motor_current')) >= 2)
    finally:
        client.close()
        code, output = stop_node(process)
        line.stop()
    assert code == 0, output
    stopped = [text for text in output.splitlines() if f'wire trace {trace} stopped' in text]
    assert len(stopped) == 1, output
    assert 'No such file or directory' in stopped[0]
