"""
Reading a cell file's text into plain data, safely and fast.

A cell file is the one input a user writes, so ``read_cell_yaml`` bounds what reading it
costs and says what is wrong in a message of bounded size:

- files over ``MAX_BYTES`` are refused before parsing;
- the node tree is composed here from the parser's events, iteratively, refusing nesting
  deeper than ``MAX_DEPTH`` (libyaml's own composer recurses in C and crashes the process
  on some 10**5 levels; PyYAML's raises RecursionError) and documents that expand, aliases
  counted each time they are used, to more than ``MAX_NODES`` nodes ("billion laughs");
  aliases stay shared nodes, so composing costs what the text costs;
- duplicate mapping keys, which YAML loaders silently collapse, are refused with their
  key path (``stations.loadport2: duplicate key ...``);
- numbers are read as YAML 1.2 writes them: ``1e-3``, ``1E3``, ``.5``, ``-.5``, ``+1e3`` and
  ``1.0e308`` are floats, ``010`` is ten, ``0x10``, ``0o10`` and ``0b10`` are ints; underscores
  (``1_000``) are still allowed; YAML 1.1 sexagesimal (``1:30``) is a string;
- only then are Python objects built, by PyYAML's safe constructor.

libyaml's parser is used when PyYAML has it, PyYAML's pure-Python one otherwise; both give
the same data and the same messages from this module (YAML syntax errors are worded by the
parser that found them).
"""

import codecs
import os
from pathlib import Path
import re
import stat
from typing import Optional, Union

from wafer_planner_ros.cell import schema
from wafer_planner_ros.errors import CellError
import yaml
from yaml.events import AliasEvent, DocumentStartEvent, MappingStartEvent, ScalarEvent
from yaml.events import SequenceStartEvent, StreamEndEvent
from yaml.nodes import MappingNode, ScalarNode, SequenceNode

MAX_BYTES = 4 * 1024 * 1024
"""Largest cell file read (bytes); the default cell is a few kilobytes."""
MAX_NODES = 100_000
"""Most YAML nodes (scalars, lists, mappings) a file may expand to, aliases expanded."""
MAX_DEPTH = 64
"""Deepest nesting of lists and mappings; a cell needs 4."""
MAX_KEY = schema.BRIEF
"""Longest mapping key (characters): keys become key paths, which every message quotes."""
MAX_INT_DIGITS = 640
"""Longest integer read (digits): no float holds more than 309, and Python's ``int()``
refuses long decimal strings (``sys.set_int_max_str_digits`` may lower that to 640)."""
MAX_MESSAGE = 600
"""Longest message quoted from the YAML parser (characters)."""

HAVE_LIBYAML = hasattr(yaml, 'CSafeLoader')

_INT = 'tag:yaml.org,2002:int'
_FLOAT = 'tag:yaml.org,2002:float'
_MERGE = 'tag:yaml.org,2002:merge'

_FLOAT_RE = re.compile(r"""^(?:[-+]?[0-9][0-9_]*\.[0-9_]*(?:[eE][-+]?[0-9]+)?
                            |[-+]?\.[0-9][0-9_]*(?:[eE][-+]?[0-9]+)?
                            |[-+]?[0-9][0-9_]*[eE][-+]?[0-9]+
                            |[-+]?\.(?:inf|Inf|INF)
                            |\.(?:nan|NaN|NAN))$""", re.X)
_INT_RE = re.compile(r"""^(?:[-+]?[0-9][0-9_]*
                          |[-+]?0x[0-9a-fA-F][0-9a-fA-F_]*
                          |[-+]?0o[0-7][0-7_]*
                          |[-+]?0b[01][01_]*)$""", re.X)


def read_cell_yaml(text: Union[bytes, str], source: str,
                   libyaml: Optional[bool] = None) -> object:
    """
    Return the plain data (dicts, lists, scalars) of a cell file's text.

    ``source`` names the file in messages. ``libyaml`` picks the parser: None uses libyaml
    when PyYAML has it, False the pure-Python parser, True libyaml (ImportError without it).
    Raise CellError for a file too big, not UTF-8 (or UTF-16 with a byte-order mark), not
    valid YAML, expanding beyond ``MAX_NODES``, nested beyond ``MAX_DEPTH``, with a key
    written twice or longer than ``MAX_KEY``, or with an integer beyond ``MAX_INT_DIGITS``.
    """
    if libyaml and not HAVE_LIBYAML:
        raise ImportError('PyYAML is installed without libyaml (yaml.CSafeLoader)')
    loader_class = _CLoader if (HAVE_LIBYAML if libyaml is None else libyaml) else _PyLoader
    text = _text(text, source)
    loader = None
    try:
        loader = loader_class(text)  # PyYAML's reader checks the characters here
        root = _compose(loader, source)
        return None if root is None else loader.construct_document(root)
    except CellError:
        raise
    except yaml.YAMLError as exc:
        raise CellError(source, _yaml_message(exc)) from None
    except (ValueError, TypeError, OverflowError) as exc:  # a constructor's, e.g. 2001-13-01
        raise CellError(source, _cap(f'not valid YAML: {exc}')) from None
    finally:
        if loader is not None:
            loader.dispose()


def read_cell_file(path) -> bytes:
    """
    Return the bytes of the cell file at ``path``, reading at most MAX_BYTES + 1 of them.

    Raise CellError for a file that cannot be read, is not a regular file (a FIFO or
    ``/dev/zero`` would never end), or is over the size limit, before reading more of it.
    """
    path = Path(path)
    try:
        # Non-blocking: opening a FIFO for reading would otherwise wait for a writer.
        with open(os.open(path, os.O_RDONLY | os.O_NONBLOCK), 'rb') as stream:
            if not stat.S_ISREG(os.fstat(stream.fileno()).st_mode):
                raise CellError(str(path), 'cannot read: not a regular file')
            data = stream.read(MAX_BYTES + 1)
    except OSError as exc:
        raise CellError(str(path), f'cannot read: {exc.strerror or exc}') from None
    if len(data) > MAX_BYTES:
        raise _too_big(f'over {MAX_BYTES:,} bytes', str(path))
    return data


def _text(text: Union[bytes, str], source: str) -> str:
    """Return the file's text as str after checking its size and encoding."""
    if isinstance(text, str):
        if len(text) > MAX_BYTES:  # each character is one UTF-8 byte or more: skip encoding
            raise _too_big(f'{len(text):,} characters', source)
        try:
            size = len(text.encode('utf-8'))
        except UnicodeEncodeError as exc:
            raise CellError(source, f'not valid text: {exc.reason} at character '
                                    f'{exc.start:,}') from None
        if size > MAX_BYTES:
            raise _too_big(f'{size:,} bytes', source)
        return text
    data = bytes(text)
    if len(data) > MAX_BYTES:
        raise _too_big(f'{len(data):,} bytes', source)
    # YAML allows UTF-16 with a byte-order mark; PyYAML read it before this module did.
    utf16 = data.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE))
    encoding = 'utf-16' if utf16 else 'utf-8-sig'
    try:
        return data.decode(encoding)
    except UnicodeDecodeError as exc:
        line = data.count(b'\n', 0, exc.start) + 1
        raise CellError(source, f'not {"UTF-16" if utf16 else "UTF-8"} text: byte '
                                f'0x{data[exc.start]:02x} at line {line:,} (byte {exc.start:,}); '
                                f'save the file as UTF-8') from None


def _too_big(size: str, source: str) -> CellError:
    return CellError(source, f'the file is {size}, more than a cell file may be '
                             f'({MAX_BYTES:,} bytes, {MAX_BYTES // 1024 // 1024} MiB)')


class _Frame:
    """A list or mapping being composed."""

    __slots__ = ('node', 'anchor', 'start', 'key', 'name', 'seen')

    def __init__(self, node, anchor, start):
        self.node = node
        self.anchor = anchor
        self.start = start
        """Expanded nodes counted before this one."""
        self.key = None
        """A mapping's key node whose value is being composed; None while a key is."""
        self.name = None
        """That key as it appears in key paths."""
        self.seen = {} if isinstance(node, MappingNode) else None
        """A mapping's keys so far, each with the node that first wrote it."""


def _compose(loader, source: str):
    """Return the root node of the one document in ``loader``'s stream, or None if empty."""
    get_event, resolve = loader.get_event, loader.resolve
    get_event()  # stream start
    event = get_event()
    if isinstance(event, StreamEndEvent):
        return None
    anchors, sizes, stack = {}, {}, []  # sizes: expanded size of each completed anchor
    count = 0
    while True:
        event = get_event()
        kind = type(event)
        if kind is ScalarEvent:
            tag = event.tag
            if tag is None or tag == '!':
                tag = resolve(ScalarNode, event.value, event.implicit)
            node = ScalarNode(tag, event.value, event.start_mark, event.end_mark,
                              style=event.style)
            if tag == _INT and len(event.value) > MAX_INT_DIGITS:
                raise CellError(_path(stack) or source,
                                f'an integer of {len(event.value):,} digits does not fit a float')
            if event.anchor is not None:
                _anchor(anchors, event, node, source)
                sizes[event.anchor] = 1
            count += 1
        elif kind is AliasEvent:
            node = anchors.get(event.anchor)
            if node is None:
                raise CellError(source, _cap(f'not valid YAML: found undefined alias '
                                             f'{event.anchor!r}{_where(event.start_mark)}'))
            if event.anchor not in sizes:
                raise CellError(_path(stack) or source, _cap(
                    f'alias {event.anchor!r} refers to a list or mapping that contains it'))
            count += sizes[event.anchor]
        elif kind is SequenceStartEvent or kind is MappingStartEvent:
            if len(stack) >= MAX_DEPTH:
                raise CellError(_path(stack) or source,
                                f'nested deeper than {MAX_DEPTH} lists and mappings')
            node_class = SequenceNode if kind is SequenceStartEvent else MappingNode
            tag = event.tag
            if tag is None or tag == '!':
                tag = resolve(node_class, None, event.implicit)
            node = node_class(tag, [], event.start_mark, None, flow_style=event.flow_style)
            if event.anchor is not None:
                _anchor(anchors, event, node, source)
            stack.append(_Frame(node, event.anchor, count))
            count += 1
            if count > MAX_NODES:
                raise _too_many(stack, source)
            continue
        else:  # the end of a list or mapping
            frame = stack.pop()
            node = frame.node
            node.end_mark = event.end_mark
            if frame.anchor is not None:
                sizes[frame.anchor] = count - frame.start
        if count > MAX_NODES:
            raise _too_many(stack, source)
        if not stack:
            break
        parent = stack[-1]
        if parent.seen is None:
            parent.node.value.append(node)
        elif parent.key is None:
            _add_key(parent, node, loader, stack, source)
        else:
            parent.node.value.append((parent.key, node))
            parent.key = None
    get_event()  # document end
    event = get_event()
    if isinstance(event, DocumentStartEvent):
        raise CellError(source, f'holds a second YAML document{_where(event.start_mark)}; '
                                f'a cell file is one document')
    return node


def _anchor(anchors, event, node, source) -> None:
    if event.anchor in anchors:  # as PyYAML's composer
        raise CellError(source, _cap(f'not valid YAML: found duplicate anchor '
                                     f'{event.anchor!r}{_where(event.start_mark)}'))
    anchors[event.anchor] = node


def _add_key(frame: _Frame, node, loader, stack, source: str) -> None:
    """Make ``node`` the next key of the mapping ``frame``, refusing one written twice."""
    where = _path(stack) or source
    if not isinstance(node, ScalarNode):
        raise CellError(where, f'a key must be a name, not a list or mapping'
                               f'{_where(node.start_mark)}')
    if len(node.value) > MAX_KEY:
        raise CellError(where, f'a key of {len(node.value):,} characters is longer than '
                               f'{MAX_KEY} ({schema.brief(node.value, 60)})')
    frame.key = node
    if node.tag == _MERGE:  # '<<: *defaults': the explicit keys override merged ones
        frame.name = '<<'
        return
    # Compare keys as the dict will: 'a' and "a" collide, and so do 1 and 0x1.
    key = node.value if node.tag == 'tag:yaml.org,2002:value' else \
        loader.construct_object(node)
    frame.name = schema.join('', key)
    try:
        first = frame.seen.setdefault(key, node)
    except TypeError:  # unhashable: the constructor will say so
        return
    if first is not node:
        raise CellError(_path(stack), f'duplicate key (first at line {first.start_mark.line + 1}'
                                      f', again at line {node.start_mark.line + 1})')


def _path(stack) -> str:
    """Return the key path of the node being composed, as schema writes it."""
    path = ''
    for frame in stack:
        if frame.seen is None:
            path = f'{path}[{len(frame.node.value)}]'
        elif frame.key is not None:
            path = schema.join(path, frame.name)
    if len(path) > MAX_MESSAGE:
        path = f'{path[:MAX_MESSAGE // 2]}...{path[-MAX_MESSAGE // 4:]}'
    return path


def _too_many(stack, source: str) -> CellError:
    return CellError(source, f'expands to more than {MAX_NODES:,} YAML nodes, the limit for '
                             f'a cell file (an alias counts the nodes it repeats each time it '
                             f'is used); the limit was reached at {_path(stack) or "the top"}')


def _yaml_message(exc: yaml.YAMLError) -> str:
    """Return a one-line message for a YAML error, without the parser's snippets."""
    if not isinstance(exc, yaml.MarkedYAMLError):
        return _cap(f'not valid YAML: {exc}')
    problem = exc.problem or exc.context or 'not valid YAML'
    message = f'not valid YAML: {problem}{_where(exc.problem_mark or exc.context_mark)}'
    if exc.problem and exc.context:
        message += f' ({exc.context}{_where(exc.context_mark)})'
    return _cap(message)


def _where(mark) -> str:
    return '' if mark is None else f' at line {mark.line + 1:,}, column {mark.column + 1:,}'


def _cap(message: str) -> str:
    """Return ``message`` on one line and at most ``MAX_MESSAGE`` characters."""
    message = ' '.join(message.split())
    return message if len(message) <= MAX_MESSAGE else message[:MAX_MESSAGE - 3] + '...'


def _construct_int(loader, node) -> int:
    """Return a YAML 1.2 integer: decimal even with leading zeros, or 0x, 0o, 0b."""
    value = loader.construct_scalar(node).replace('_', '')
    sign = -1 if value.startswith('-') else 1
    value = value.lstrip('+-')
    base = {'0x': 16, '0o': 8, '0b': 2}.get(value[:2].lower(), 10)
    return sign * int(value if base == 10 else value[2:], base)


def _resolvers(base) -> dict:
    """Return ``base``'s implicit resolvers with YAML 1.2 floats and ints."""
    resolvers = {first: [(tag, regexp) for tag, regexp in entries if tag not in (_INT, _FLOAT)]
                 for first, entries in base.yaml_implicit_resolvers.items()}
    for tag, regexp, first in ((_FLOAT, _FLOAT_RE, '-+0123456789.'),
                               (_INT, _INT_RE, '-+0123456789')):
        for char in first:
            resolvers.setdefault(char, []).append((tag, regexp))
    return resolvers


class _PyLoader(yaml.SafeLoader):
    """PyYAML's pure-Python safe loader with YAML 1.2 numbers."""

    yaml_implicit_resolvers = _resolvers(yaml.SafeLoader)


_PyLoader.add_constructor(_INT, _construct_int)

if HAVE_LIBYAML:
    class _CLoader(yaml.CSafeLoader):
        """libyaml's safe loader with YAML 1.2 numbers."""

        yaml_implicit_resolvers = _PyLoader.yaml_implicit_resolvers

    _CLoader.add_constructor(_INT, _construct_int)
else:
    _CLoader = _PyLoader
