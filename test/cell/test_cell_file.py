"""Reading a cell file: bounded cost and messages, duplicate keys, numbers as users write them."""

import copy
import os

import pytest
from wafer_planner_ros.cell import document as cell_file
from wafer_planner_ros.cell import schema
from wafer_planner_ros.cell.document import read_cell_yaml
from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.errors import CellError
import yaml

CELLS = [default_cell_path(), *sorted((default_cell_path().parents[1] / 'test/support/cells')
                                      .glob('*.yaml'))]
PARSERS = [pytest.param(True, id='libyaml', marks=pytest.mark.skipif(
    not cell_file.HAVE_LIBYAML, reason='PyYAML without libyaml')),
    pytest.param(False, id='python')]
MESSAGE = 4096
"""Longest acceptable message (characters)."""


@pytest.fixture(scope='module')
def default_text() -> str:
    """Return the default cell file's text."""
    return default_cell_path().read_text()


def _edit(text: str, old: str, new: str) -> str:
    assert text.count(old) == 1, old
    return text.replace(old, new)


def _refusal(text, libyaml=None) -> CellError:
    """Return the CellError reading ``text`` raises, checking its message is bounded."""
    with pytest.raises(CellError) as info:
        read_cell_yaml(text, 'cell.yaml', libyaml=libyaml)
    assert len(str(info.value)) < MESSAGE
    return info.value


def _laughs(levels=9, width=10, indent='') -> str:
    """Return the anchors of a 'billion laughs' list: ``width ** levels`` strings."""
    rows = [f'&l0 [{", ".join(["lol"] * width)}]']
    rows += [f'&l{i} [{", ".join([f"*l{i - 1}"] * width)}]' for i in range(1, levels)]
    return f',\n{indent}'.join(rows)


@pytest.mark.parametrize('libyaml', PARSERS)
def test_alias_bomb_at_the_top_level_is_refused_at_once(libyaml):
    text = f'[{_laughs()}]\n'
    assert len(text) < 1000
    error = _refusal(text, libyaml)  # counted, not expanded: bench/bench_cell.py times it
    assert error.path == 'cell.yaml'
    assert f'more than {cell_file.MAX_NODES:,} YAML nodes' in error.reason


@pytest.mark.parametrize('libyaml', PARSERS)
def test_alias_bomb_in_the_cell_name_is_refused_at_once(default_text, libyaml):
    text = _edit(default_text, 'name: efem-3lp-2ll',
                 f'name: [{_laughs(indent="         ")}]')
    error = _refusal(text, libyaml)
    assert f'more than {cell_file.MAX_NODES:,} YAML nodes' in error.reason
    assert 'reached at cell.name[' in error.reason


def test_aliases_below_the_limit_are_shared_not_refused():
    data = read_cell_yaml(f'[{_laughs(levels=4)}]\n', 'cell.yaml')  # 11,110 nodes expanded
    assert len(data[3]) == 10 and data[3][0] is data[3][9] is data[2]


def test_files_over_the_size_limit_are_refused_before_parsing():
    limit = cell_file.MAX_BYTES
    comments = ('# ' + 'x' * 97 + '\n') * (limit // 100)
    assert read_cell_yaml(comments.encode(), 'cell.yaml') is None  # just under: read
    huge = b'cell: [' + b', '.join([b'0.125'] * 7_500_000) + b']\n'  # 50 MB of valid YAML
    for text in (huge, huge.decode(), b'#' * (limit + 1), 'é' * (limit // 2 + 1)):
        error = _refusal(text)
        assert error.path == 'cell.yaml'
        assert f'({limit:,} bytes, 4 MiB)' in error.reason
    assert 'the file is 4,194,306 bytes' in _refusal('é' * (limit // 2 + 1)).reason
    assert 'the file is 52,500,007 bytes' in _refusal(huge).reason


def test_a_file_near_the_size_limit_is_read(default_text):  # bench/bench_cell.py times it
    points = ', '.join(f'[{i * 1e-5:.6f}, 0.25]' for i in range(30_000))  # 90,000 nodes
    text = _edit(default_text, 'obstacles: []', f'obstacles: [[{points}]]')
    text += ('# ' + 'x' * 97 + '\n') * ((cell_file.MAX_BYTES - len(text)) // 100)
    assert len(text) > cell_file.MAX_BYTES - 100
    data = read_cell_yaml(text, 'cell.yaml')
    assert len(data['cell']['obstacles'][0]) == 30_000


@pytest.mark.parametrize('libyaml', PARSERS)
@pytest.mark.parametrize('old, new, path', [
    ('stations:', 'robot: {}\nstations:', 'robot'),
    ('  loadlock1:', '  loadport2: {wafer_center: [0.0, 0.2], heading: 1.5708}\n  loadlock1:',
     'stations.loadport2'),
    ('  loadlock1:', "  'loadport2': {wafer_center: [0.0, 0.2], heading: 1.5708}\n  loadlock1:",
     'stations.loadport2'),
    ('[-0.505, 0.26], heading: 1.5708,', '[-0.505, 0.26], heading: 1.5708, heading: 0.0,',
     'stations.loadport1.heading'),
], ids=['top level', 'station', 'quoted station', 'in a station'])
def test_duplicate_keys_are_refused_with_their_key_path(default_text, old, new, path, libyaml):
    error = _refusal(_edit(default_text, old, new), libyaml)
    assert error.path == path
    assert str(error).startswith(f'{path}: duplicate key (first at line ')


def test_keys_that_are_equal_once_read_are_duplicates_and_merge_keys_are_not():
    assert _refusal('stations: {1: a, 0x1: b}\n').path == 'stations.1'
    data = read_cell_yaml('base: &b {heading: 1.0, elbow: 1}\ns: {<<: *b, heading: 2.0}\n', 'c')
    assert data['s'] == {'heading': 2.0, 'elbow': 1}


FLOATS = [('1e-3', 1e-3), ('1E3', 1e3), ('-2.5e-4', -2.5e-4), ('.5', 0.5), ('-.5', -0.5),
          ('1.0e308', 1.0e308), ('+1e3', 1e3), ('1.5', 1.5), ('1.', 1.0), ('1_000.5', 1000.5),
          ('1.0e+3', 1e3), ('.inf', float('inf')), ('-.Inf', float('-inf'))]
INTS = [('1', 1), ('-7', -7), ('+5', 5), ('0', 0), ('010', 10), ('09', 9), ('0x10', 16),
        ('0o10', 8), ('0b10', 2), ('1_000', 1000)]


@pytest.mark.parametrize('libyaml', PARSERS)
def test_numbers_are_read_as_yaml_1_2_writes_them(libyaml):
    values = FLOATS + INTS + [('1:30', '1:30'), ('1e', '1e'), ('e3', 'e3'), ('.', '.'),
                              ('0x', '0x'), ('1.2.3', '1.2.3')]
    text = ''.join(f'k{i}: {written}\n' for i, (written, _) in enumerate(values))
    data = read_cell_yaml(text, 'cell.yaml', libyaml=libyaml)
    for i, (written, expected) in enumerate(values):
        assert data[f'k{i}'] == expected and type(data[f'k{i}']) is type(expected), written
    nan = read_cell_yaml('x: .nan', 'cell.yaml', libyaml=libyaml)['x']
    assert nan != nan


@pytest.mark.parametrize('written', ['1.5e-1', '15e-2', '.15', '+1.5E-1'])
def test_a_cell_with_exponent_numbers_validates(default_text, written):
    text = _edit(default_text, 'wafer_radius: 0.15', f'wafer_radius: {written}')
    text = _edit(text, 'heading: 1.5708, port: {depth: 0.35}}\n  loadport3',
                 'heading: 15708e-4, port: {depth: 0.35}}\n  loadport3')
    cell = Cell.from_dict(read_cell_yaml(text, 'cell.yaml'))
    assert cell.robot.wafer_radius == 0.15
    assert cell.stations['loadport2'].spec['heading'] == 1.5708


def test_the_largest_floats_are_read(default_text):
    text = _edit(default_text, 'wafer_radius: 0.15', 'wafer_radius: 1.0e308')
    assert read_cell_yaml(text, 'cell.yaml')['robot']['wafer_radius'] == 1.0e308
    assert schema.number(read_cell_yaml('x: 1.7976931348623157e308', 'c')['x'], 'x') > 1e308


def test_an_integer_no_float_holds_names_its_key(default_text):
    digits = '1' + '0' * 399
    data = read_cell_yaml(_edit(default_text, 'wafer_radius: 0.15', f'wafer_radius: {digits}'),
                          'cell.yaml')
    with pytest.raises(CellError) as info:
        Cell.from_dict(data)
    assert str(info.value) == 'robot.wafer_radius: 10000...0000 (400 digits) does not fit a float'
    for value in (2 ** 1024, -2 ** 1024, 10 ** 5000):
        with pytest.raises(CellError, match='does not fit a float') as info:
            schema.number(value, 'robot.wafer_radius')
        assert len(str(info.value)) < 200
    assert schema.number(2 ** 1023, 'x') == 2.0 ** 1023
    with pytest.raises(CellError, match='must be a number, got True'):
        schema.number(True, 'x')
    longer = _edit(default_text, 'wafer_radius: 0.15', f'wafer_radius: {"9" * 5000}')
    error = _refusal(longer)  # beyond what Python's int() reads: refused by the reader
    assert str(error) == 'robot.wafer_radius: an integer of 5,000 digits does not fit a float'


def test_messages_quote_huge_values_briefly():
    shared = ['lol'] * 10
    for _ in range(8):
        shared = [shared] * 10  # 10**9 strings, as an alias bomb builds them
    huge_text = 'n' * 3_000_000
    calls = [lambda: schema.text(shared, 'cell.name'),
             lambda: schema.text(huge_text, 'cell.name'),
             lambda: schema.number(shared, 'robot.wafer_radius'),
             lambda: schema.number(huge_text, 'robot.wafer_radius'),
             lambda: schema.vector(shared, 'robot.base', 2),
             lambda: schema.mapping({huge_text: 1}, 'robot', optional=('base',))]
    for call in calls:  # a message built from the whole of ``shared`` would never end
        with pytest.raises(CellError) as info:
            call()
        assert len(str(info.value)) < 500
    assert len(schema.brief(shared)) <= schema.BRIEF
    assert schema.brief(0.15) == '0.15' and schema.brief('a') == "'a'"


def test_names_longer_than_the_limit_are_refused_with_their_length():
    assert schema.text('n' * schema.MAX_TEXT, 'cell.name') == 'n' * schema.MAX_TEXT
    with pytest.raises(CellError) as info:
        schema.text('n' * 5000, 'cell.name')
    assert str(info.value).startswith('cell.name: must be at most 200 characters, got 5,000 ')


def test_long_keys_are_refused(default_text):
    error = _refusal(_edit(default_text, '  loadport1:', f'  {"p" * 300}:'))
    assert error.path == 'stations' and 'a key of 300 characters' in error.reason


@pytest.mark.parametrize('libyaml', PARSERS)
@pytest.mark.parametrize('text, reason', [
    (b'cell: {name: caf\xe9}\n', 'not UTF-8 text: byte 0xe9 at line 1'),
    ('cell: [unclosed\n', 'not valid YAML: '),
    ('cell:\n\tname: x\n', 'not valid YAML: '),
    ('cell: [' + 'x' * 3_000_000 + '\n', 'not valid YAML: '),
    ('cell: *' + 'a' * 3_000_000 + '\n', 'not valid YAML: found undefined alias'),
    ('cell: !' + 't' * 1_000_000 + ' x\n', 'not valid YAML: '),
    ('cell: 1\n---\ncell: 2\n', 'holds a second YAML document at line 2'),
    ('cell: &x [*x]\n', "alias 'x' refers to a list or mapping that contains it"),
    ('cell: 2001-13-01\n', 'not valid YAML: month must be in 1..12'),
    ('cell: !!python/object/apply:os.system [ls]\n', 'not valid YAML: could not determine'),
    ('[' * 200_000 + ']' * 200_000, 'nested deeper than 64'),  # libyaml's composer: SIGSEGV
    ('- ' * 100_000 + 'x\n', 'nested deeper than 64'),
], ids=['latin-1', 'syntax', 'tab', 'long line', 'long alias', 'long tag', 'two documents',
        'recursive', 'bad date', 'python tag', 'deep flow', 'deep block'])
def test_unreadable_text_gives_a_bounded_message(text, reason, libyaml):
    assert reason in str(_refusal(text, libyaml))


@pytest.mark.parametrize('libyaml', PARSERS)
@pytest.mark.parametrize('path', CELLS, ids=[p.stem for p in CELLS])
def test_both_parsers_read_the_cells_as_pyyaml_did(path, libyaml):
    data = read_cell_yaml(path.read_bytes(), str(path), libyaml=libyaml)
    assert data == yaml.safe_load(path.read_text())
    assert Cell.from_dict(copy.deepcopy(data)).digest == Cell.from_yaml(path).digest


def test_both_parsers_give_the_same_data():
    if not cell_file.HAVE_LIBYAML:
        pytest.skip('PyYAML without libyaml')
    text = ''.join(f'k{i}: {written}\n' for i, (written, _) in enumerate(FLOATS + INTS))
    text += 'd: &d {a: [1, {b: "x"}], c: null, e: yes, f: 2001-12-14}\ng: {<<: *d, a: ~}\n'
    for path in CELLS:
        text += f'{path.stem}:\n' + ''.join(f'  {line}\n' for line in path.read_text()
                                            .splitlines() if not line.lstrip().startswith('#'))
    assert read_cell_yaml(text, 'c', libyaml=True) == read_cell_yaml(text, 'c', libyaml=False)


def test_encodings_and_empty_files():
    utf8 = 'cell: {name: café}\n'
    for data in (utf8, utf8.encode(), '\ufeff' + utf8, ('\ufeff' + utf8).encode(),
                 utf8.encode('utf-16')):
        assert read_cell_yaml(data, 'c') == {'cell': {'name': 'café'}}
    for empty in ('', b'', '# nothing\n', '---\n'):
        assert read_cell_yaml(empty, 'c') is None
    assert 'not valid text' in str(_refusal('cell: "\ud800"'))


def test_only_a_regular_file_of_at_most_the_limit_is_read(tmp_path, default_text):
    fifo = tmp_path / 'cell.fifo'
    os.mkfifo(fifo)  # opening it to read would wait for a writer for ever
    for path in (fifo, '/dev/zero', tmp_path):
        with pytest.raises(CellError) as info:
            Cell.from_yaml(path)
        assert info.value.path == str(path) and 'cannot read' in info.value.reason
    big = tmp_path / 'big.yaml'
    big.write_text(default_text + '#' * cell_file.MAX_BYTES)
    with pytest.raises(CellError, match='more than a cell file may be'):
        Cell.from_yaml(big)
    assert cell_file.read_cell_file(default_cell_path()) == default_cell_path().read_bytes()
