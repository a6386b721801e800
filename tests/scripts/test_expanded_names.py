"""A script whose expansion is not XML: xacro:element and xacro:attribute take any string
as a name, and expressions any character as a value; the expanded text is then refused
with one line naming file:line, not with lxml's traceback."""

from __future__ import annotations

import pytest

from .test_hardening import V, assert_error, recon, run_case, tree  # noqa: F401  (tree: the fixture)

HINT = "xacro:element and xacro:attribute need XML names"

CASES = [
    ("element name with a digit first", '<xacro:element xacro:name="1abc"/>',
     "s.xml:2: the expansion produced an invalid element name '1abc' (in an element made inside the element of "
     "this line)"),
    ("element name with a space", '<xacro:element xacro:name="a b"/>', "invalid element name 'a b'"),
    ("element name with two colons", '<xacro:element xacro:name="x:y:z"/>', "invalid element name 'x:y:z'"),
    ("element name with an undeclared prefix", '<xacro:element xacro:name="q:scan"/>',
     "element name 'q:scan' whose prefix 'q' is not declared"),
    ("element name from a property",
     '<xacro:property name="n" value="scan here"/>\n  <xacro:element xacro:name="${n}"/>',
     "s.xml:2: the expansion produced an invalid element name 'scan here'"),
    ("element name too long", '<xacro:element xacro:name="' + "a" * 50_001 + '"/>',
     "s.xml:2: the expansion produced an element name of 50001 characters, more than the 50000"),
    ("attribute name with a space", '<scan name="a">\n    <xacro:attribute name="a b" value="1"/>\n  </scan>',
     "s.xml:4: the expansion produced an invalid attribute name 'a b'; " + HINT),
    ("attribute of the root", '<xacro:attribute name="a b" value="1"/>', "s.xml:2: the expansion produced an invalid "
     "attribute name 'a b'"),
    ("control character in a value", '<scan name="${\'\\x01\'}"/>',
     "s.xml:4: the expansion produced the character U+0001, which XML does not allow, in the attribute 'name'"),
    ("control character in a text", "<scan>${'\\x02'}</scan>", "s.xml:4: the expansion produced the character U+0002"),
]


@pytest.mark.parametrize("body, words", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_an_expansion_that_is_not_xml_is_one_line(tree, capsys, body, words):  # noqa: F811
    code, _, err = run_case(tree, capsys, recon(body), V)
    assert_error(code, err, 1, words, HINT)


def test_an_invalid_name_made_in_a_macro_names_the_macro_body(tree, capsys):  # noqa: F811
    body = ('<xacro:macro name="m" params="n">\n    <scan name="a">\n      <xacro:attribute name="${n}" value="1"/>\n'
            '    </scan>\n  </xacro:macro>\n  <xacro:m n="x y"/>')
    code, _, err = run_case(tree, capsys, recon(body), V)
    assert_error(code, err, 1, "s.xml:5: the expansion produced an invalid attribute name 'x y'")


def test_valid_names_made_by_xacro_still_load(tree, capsys):  # noqa: F811
    body = ('<xacro:element xacro:name="move" focus="0 0 0.8" radius="0.6" theta="40">\n'
            '    <xacro:attribute name="phi" value="0"/>\n  </xacro:element>\n  <scan name="a"/>')
    code, out, err = run_case(tree, capsys, recon(body), V)
    assert code == 0 and err == "" and "valid" in out, (out, err)
