"""Gait parameters and the /gait/command schema.

Gait parameters: every bad value is refused with its name and range, the admissible duty
factors follow the seeds (Kurazume (25), crawl > 3/4), the robot limits come from its YAML, and
the JSON Schema of /gait/command agrees with the dataclass.
"""

import json
import math
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from planning_helpers import robot

from gait_nodes.errors import GaitCommandError, GaitParameterError
from gait_nodes.planning.gait_params import (
    CHOICE_FIELDS,
    NUMERIC_RANGES,
    GaitParameters,
    command_id_of,
    command_schema,
    duty_factor_bounds,
    nominal_stance_width_m,
    parameters_from_mapping,
    parse_command,
    parse_gait_command,
)
from gait_nodes.robot.description import load_robot_description

QUADRUPED = robot('quadruped')
BIPED = robot('biped')


def test_defaults_take_the_robot_stance_and_heights():
    quad = GaitParameters.for_robot(QUADRUPED)
    assert quad.step_width_m == pytest.approx(1.0)
    assert (quad.com_height_m, quad.body_height_m) == (0.6, 0.65)
    biped = GaitParameters.for_robot(BIPED, duty_factor=0.9)
    assert biped.step_width_m == pytest.approx(0.2)
    assert biped.com_height_m == 0.814
    assert quad.cycle_s == 2 * quad.step_period_s
    assert quad.swing_s == pytest.approx((1 - quad.duty_factor) * quad.cycle_s)


def test_default_stride_fits_the_robot_reach():
    # The class default (0.3 m), or the robot's reach when that is shorter (a Go2: 0.2 m); a
    # robot whose gaits reach differently: the longest (RoboSimian's static crawl: 0.3 m, its
    # other gaits 0.2 m; each steps at most its own, tested in test_gait_choice).
    default = GaitParameters.__dataclass_fields__['step_length_m'].default
    go2 = load_robot_description('go2')
    robosimian = load_robot_description('robosimian')
    for description in (QUADRUPED, BIPED, go2, robosimian):
        params = GaitParameters.for_robot(description)
        assert params.step_length_m == min(default, description.longest_step_m)
        params.check_robot(description)
    assert robosimian.reach.max_step_length_m == 0.2
    assert robosimian.max_step_length_m('static_crawl') == 0.3
    assert GaitParameters.for_robot(robosimian).step_length_m == 0.3
    assert GaitParameters.for_robot(go2).step_length_m == 0.2
    assert GaitParameters.for_robot(go2, step_length_m=0.1).step_length_m == 0.1


def test_auto_resolves_to_the_robot_first_gait():
    assert GaitParameters.for_robot(QUADRUPED).resolved_gait(QUADRUPED) == 'crawl'
    assert GaitParameters.for_robot(BIPED, duty_factor=0.9).resolved_gait(BIPED) == 'biped'


@pytest.mark.parametrize('name', sorted(NUMERIC_RANGES))
@pytest.mark.parametrize('bad', [0.0, -0.1, math.nan, math.inf, -math.inf, True, '0.3', None])
def test_every_number_refuses_zero_negative_non_finite_and_wrong_types(name, bad):
    with pytest.raises(GaitParameterError, match=name):
        GaitParameters.for_robot(QUADRUPED, **{name: bad})


@pytest.mark.parametrize('name', sorted(CHOICE_FIELDS))
def test_choices_refuse_unknown_values(name):
    with pytest.raises(GaitParameterError, match=name):
        GaitParameters.for_robot(QUADRUPED, **{name: 'gallop'})
    with pytest.raises(GaitParameterError, match=name):
        GaitParameters.for_robot(QUADRUPED, **{name: 3})


def test_crawl_needs_a_duty_factor_above_three_quarters():
    for beta in (0.75, 0.6, 1.0):
        with pytest.raises(GaitParameterError, match='duty_factor'):
            GaitParameters.for_robot(QUADRUPED, gait='crawl', duty_factor=beta)
    GaitParameters.for_robot(QUADRUPED, gait='crawl', duty_factor=0.76)


def test_trot_needs_a_duty_factor_above_one_half():
    with pytest.raises(GaitParameterError, match=r'Kurazume \(25\)'):
        GaitParameters.for_robot(QUADRUPED, gait='trot', duty_factor=0.5)
    GaitParameters.for_robot(QUADRUPED, gait='trot', duty_factor=0.51)


@settings(max_examples=60, deadline=None)
@given(width=st.floats(0.12, 0.5), margin=st.floats(0.001, 0.049))
def test_biped_duty_factor_bound_is_kurazume_25(width, margin):
    params = GaitParameters(step_width_m=width, zmp_margin_m=margin, com_height_m=0.8,
                            body_height_m=0.78)
    low, high = duty_factor_bounds('biped', BIPED, params)
    # (25): beta > (1 + alpha) / 2 with the sole's inner edge at alpha D, D = w / 2.
    sway = width / 2
    inner_edge = sway - (BIPED.foot_radius_m - margin)
    alpha = inner_edge / sway
    assert low == pytest.approx(max(0.5, (1 + alpha) / 2))
    assert high == 1.0
    if low + 1e-3 < 1.0:
        params.replace(duty_factor=low + 1e-3).check_robot(BIPED)
    with pytest.raises(GaitParameterError, match='duty_factor'):
        params.replace(duty_factor=max(low - 1e-3, 0.01)).check_robot(BIPED)


def test_a_gait_the_robot_cannot_do_is_refused():
    with pytest.raises(GaitParameterError, match="'trot' is not possible"):
        GaitParameters.for_robot(BIPED, gait='trot', duty_factor=0.9)
    with pytest.raises(GaitParameterError, match="'biped' is not possible"):
        GaitParameters.for_robot(QUADRUPED, gait='biped')


def test_steps_beyond_reach_are_refused():
    with pytest.raises(GaitParameterError, match='max_step_length_m'):
        GaitParameters.for_robot(QUADRUPED, step_length_m=0.51)
    GaitParameters.for_robot(QUADRUPED, step_length_m=0.5)
    nominal = nominal_stance_width_m(QUADRUPED)
    with pytest.raises(GaitParameterError, match='max_step_width_m'):
        GaitParameters.for_robot(QUADRUPED, step_width_m=nominal + 0.41)
    with pytest.raises(GaitParameterError, match='step_width_m'):
        GaitParameters.for_robot(BIPED, step_width_m=0.09, duty_factor=0.95)  # feet overlap


def test_margin_must_fit_the_support():
    with pytest.raises(GaitParameterError, match='foot radius'):
        GaitParameters.for_robot(QUADRUPED, gait='trot', duty_factor=0.7, zmp_margin_m=0.055)
    with pytest.raises(GaitParameterError, match='crawl'):
        GaitParameters.for_robot(QUADRUPED, gait='crawl', zmp_margin_m=0.5)


def test_parse_command_refuses_each_kind_of_bad_text():
    cases = {
        '{"step_length_m": 0.2': 'invalid JSON',
        '[1, 2]': 'JSON object',
        '"trot"': 'JSON object',
        '{"step_lenght_m": 0.2}': 'unknown key',
        '{"step_length_m": "0.2"}': "not of type 'number'",
        '{"duty_factor": true}': "not of type 'number'",
        '{"gait": 3}': 'gait',
        '{"step_length_m": NaN}': 'finite',
        '{"step_period_s": Infinity}': 'finite',
        '{"step_period_s": 0}': 'minimum',
        '{"step_length_m": -0.3}': 'minimum',
    }
    for text, reason in cases.items():
        with pytest.raises(GaitCommandError, match=reason):
            parse_command(text)


def test_parse_command_reads_integers_as_numbers():
    assert parse_command('{"step_period_s": 1, "gait": "trot"}') == {'step_period_s': 1.0,
                                                                       'gait': 'trot'}
    assert parse_command('{}') == {}


def test_parameters_from_mapping_checks_the_robot_and_leaves_the_base_alone():
    base = GaitParameters.for_robot(QUADRUPED)
    changed = parameters_from_mapping(base, {'gait': 'trot', 'duty_factor': 0.6}, QUADRUPED)
    assert (changed.gait, changed.duty_factor) == ('trot', 0.6)
    with pytest.raises(GaitParameterError):
        parameters_from_mapping(base, {'gait': 'trot'}, QUADRUPED.__class__(
            **{**QUADRUPED.__dict__, 'gaits': ('crawl',)}))
    with pytest.raises(GaitParameterError, match='unknown'):
        parameters_from_mapping(base, {'speed': 1.0}, QUADRUPED)
    assert base == GaitParameters.for_robot(QUADRUPED)


def test_schema_agrees_with_the_dataclass():
    schema = command_schema()
    properties = schema['properties']
    assert schema['additionalProperties'] is False
    assert list(properties) == ['id', *GaitParameters.__dataclass_fields__]
    assert properties['id'] == {**properties['id'], 'type': 'string', 'minLength': 1,
                                'maxLength': 128}
    for name, (low, high, _) in NUMERIC_RANGES.items():
        assert properties[name]['type'] == 'number'
        assert properties[name]['exclusiveMinimum'] == low
        assert properties[name].get('maximum', properties[name].get('exclusiveMaximum')) == high
    for name, choices in CHOICE_FIELDS.items():
        assert properties[name]['enum'] == list(choices)
    # Every default passes the schema.
    defaults = GaitParameters.for_robot(QUADRUPED).to_dict()
    assert parse_command(json.dumps(defaults)) == defaults
    assert parse_gait_command(json.dumps({'id': 'a-1', **defaults})) == ('a-1', defaults)


@pytest.mark.parametrize('text, match', [
    ('{"step_length_m": 0.1, "step_length_m": 0.2}', r"\['step_length_m'\] given more than once"),
    ('{"id": "a", "id": "b"}', r"\['id'\] given more than once"),
    ('{"gait": {"x": 1, "x": 2}}', r"\['x'\] given more than once"),
    ('{"id": ""}', 'id'),
    ('{"id": 7}', 'string'),
])
def test_a_key_given_twice_or_a_bad_id_is_refused(text, match):
    with pytest.raises(GaitParameterError, match=match):
        parse_gait_command(text)


def test_the_id_of_a_bad_command_is_found_for_its_answer():
    assert command_id_of('{"id": "x-1", "step_length_m": -1}') == 'x-1'
    assert command_id_of('{"id": 3}') is None
    assert command_id_of('not json') is None


def test_auto_is_the_first_gait_of_a_robot_without_limb_ik():
    # RoboSimian, with closed-form limb IK, plans each of its gaits (test_gait_choice.py); a
    # robot without it walks its first gait, and says so.
    from gait_nodes.planning.gait_params import auto_choice, auto_gait
    from gait_nodes.planning.timing_models import auto_reason

    fixture = load_robot_description(Path(__file__).parent / 'data' / 'robots' /
                                     'quadruped.yaml')
    assert auto_choice(fixture) is None
    assert auto_gait(fixture) == fixture.gaits[0]
    assert auto_reason(fixture).startswith(f'{fixture.gaits[0]}, ')
