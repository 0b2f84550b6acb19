"""Architecture: every class in the package can be read in one sitting (at most 250 lines)."""

import ast
import os

PACKAGE = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(
    os.path.abspath(__file__)))), 'drive_bridge')
MAX_CLASS_LINES = 250


def class_sizes(source: str):
    """Yield (name, first line, lines) of every class in ``source``, nested ones included."""
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ClassDef):
            yield node.name, node.lineno, node.end_lineno - node.lineno + 1


def package_files():
    for directory, _, names in os.walk(PACKAGE):
        for name in sorted(names):
            if name.endswith('.py'):
                yield os.path.join(directory, name)


def test_the_size_check_sees_a_long_class():
    body = '\n'.join(f'    x{index} = {index}' for index in range(MAX_CLASS_LINES))
    assert [size for *_, size in class_sizes(f'class Long:\n{body}\n')] == [
        MAX_CLASS_LINES + 1]


def test_no_class_in_the_package_is_over_250_lines():
    long = []
    for path in package_files():
        with open(path, encoding='utf-8') as stream:
            source = stream.read()
        long += [f'{os.path.relpath(path, PACKAGE)}:{line} {name}: {size} lines'
                 for name, line, size in class_sizes(source) if size > MAX_CLASS_LINES]
    assert long == [], 'split these into collaborators with explicit interfaces'
