"""wafer-plan-client words a node's result with units, as wafer-plan words a plan."""

from wafer_planner_ros.cli.client import described

# A ~/result's values exactly as the node sends them (strings: node.messages.result_status).
OK_VALUES = {
    'code': 'OK', 'cycle_time': '1.5853178462300374', 'initial_cycle_time': '3.0894',
    'planning_time_ms': '0.812', 'roadmap_ms': '0.1', 'roadmap_hash': '9f679c05e750f407',
    'seed': '0', 'from': 'loadport2', 'to': 'loadlock2', 'ratio_velocity': '0.45012',
    'ratio_wafer_x': '0.99871', 'min_clearance': '0.009575569580799498',
    'peak_jerk': '[167.9, 120.04, 90.5]', 'peak_wafer_jerk': '12.345', 'certified': 'True',
    'branches': '[1, -1]', 'method': 'whole-curve', 'source': 'table', 'budget': '0.0',
    'node_ms': '4.51'}


def test_an_ok_result_is_worded_with_units_and_rounded():
    assert described(OK_VALUES) == [
        'cycle time 1.585 s (λ-scaled start 3.089 s), elbow right -> elbow left (whole-curve, '
        'from the station table)',
        'min clearance 9.6 mm; limit ratios: velocity 0.450, wafer_x 0.999',
        'peak jerk 168, 120, 90 rad/s³ (joints), wafer 12.3 m/s³; proven collision-free',
        'planning 0.8 ms; answered 4.5 ms after receipt; roadmap 9f679c05e750, seed 0']


def test_joint_angle_ends_and_an_unproven_curve_say_so():
    values = dict(OK_VALUES, branches='[null, 1]', certified='False', method='knot-timing',
                  source='planned')
    lines = described(values)
    assert lines[0].startswith('cycle time 1.585 s (λ-scaled start 3.089 s), joint angles -> '
                               'elbow right (knot-timing, planned for this request)')
    assert lines[2].endswith('; NOT proven collision-free')
    lines = described(dict(values, method='whole-curve', from_optimum='True'))
    assert lines[0].endswith('(whole-curve, planned for this request, from a kept optimum '
                             'near it)')


def test_an_error_result_names_its_code_and_only_what_it_has():
    values = {'code': 'START_IN_COLLISION', 'planning_time_ms': '1.25',
              'roadmap_hash': 'abcdef0123456789', 'seed': '3', 'from': '[0.1, 0.2, 0.3]',
              'to': 'loadlock1'}
    assert described(values) == [
        'code START_IN_COLLISION', 'planning 1.2 ms; roadmap abcdef012345, seed 3']


def test_values_that_are_not_what_the_node_sends_are_worded_without_failing():
    values = dict(OK_VALUES, branches='garbage', peak_jerk='[oops', cycle_time='nan',
                  min_clearance='inf', ratio_velocity='x')
    lines = described(values)
    assert not any(line.startswith(('cycle time', 'min clearance', 'peak jerk'))
                   for line in lines), lines
    assert lines == ['planning 0.8 ms; answered 4.5 ms after receipt; roadmap 9f679c05e750, '
                     'seed 0']
