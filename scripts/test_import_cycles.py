#!/usr/bin/env python3
"""Tests of scripts/import_cycles.py on small crates written to a temp dir.

    python3 scripts/test_import_cycles.py
"""

import os
import subprocess
import sys
import tempfile
import unittest

SCRIPT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "import_cycles.py")


def run(files: dict) -> tuple:
    """(exit code, stdout) of the script on a crate made of `files` (path -> text)."""
    with tempfile.TemporaryDirectory() as root:
        for path, text in files.items():
            full = os.path.join(root, path)
            os.makedirs(os.path.dirname(full), exist_ok=True)
            with open(full, "w", encoding="utf-8") as f:
                f.write(text)
        out = subprocess.run(
            [sys.executable, SCRIPT, "--crate-root", root], capture_output=True, text=True
        )
        return out.returncode, out.stdout


class ImportCycles(unittest.TestCase):
    def test_two_files_naming_each_other(self):
        code, out = run(
            {
                "lib.rs": "pub mod a;\npub mod b;\n",
                "a.rs": "use crate::b::B;\npub struct A;\n",
                "b.rs": "pub struct B;\nfn f() { let _ = crate::a::A; }\n",
            }
        )
        self.assertEqual(code, 1, out)
        self.assertIn("cycle: a, b", out)
        self.assertIn("a -> b  (a.rs:1)", out)
        self.assertIn("b -> a  (b.rs:2)", out)

    def test_a_layered_crate_has_no_cycle(self):
        code, out = run(
            {
                "lib.rs": "pub mod a;\npub mod b;\npub mod c;\n",
                "a.rs": "use crate::{b::B, c};\n",
                "b.rs": "use crate::c::C;\npub struct B;\n",
                "c.rs": "pub struct C;\n",
            }
        )
        self.assertEqual(code, 0, out)

    def test_tests_comments_and_strings_are_not_references(self):
        code, out = run(
            {
                "lib.rs": "pub mod a;\npub mod b;\n",
                "a.rs": "use crate::b::B;\n",
                "b.rs": (
                    "// crate::a::A in a comment\n"
                    "/* and crate::a::A /* nested */ here */\n"
                    'const S: &str = "crate::a::A";\n'
                    'const R: &str = r#"crate::a::A"#;\n'
                    "pub struct B;\n"
                    "#[cfg(test)]\nmod tests {\n    use crate::a::A;\n    fn f() { let _ = '{'; }\n}\n"
                    "#[cfg(test)]\nmod more;\n"
                ),
                "b/more.rs": "use crate::a::A;\n",
            }
        )
        self.assertEqual(code, 0, out)

    def test_siblings_inside_a_folder(self):
        code, out = run(
            {
                "lib.rs": "pub mod tasks;\n",
                "tasks/mod.rs": "pub mod chat;\npub mod scene;\npub use scene::View;\npub struct Config;\n",
                "tasks/chat.rs": "use super::scene::View;\nuse crate::tasks::Config;\n",
                "tasks/scene.rs": "use crate::tasks::chat;\npub struct View;\n",
            }
        )
        self.assertEqual(code, 1, out)
        self.assertIn("cycle: tasks::chat, tasks::scene", out)
        # The parent and its children are no edge: only the one cycle.
        self.assertIn("1 cycle(s)", out)

    def test_reexports_resolve_to_the_defining_module(self):
        code, out = run(
            {
                "lib.rs": "pub mod units;\npub mod validate;\npub use validate::Problem;\n",
                "units.rs": "use crate::Problem;\npub struct Cm;\n",
                "validate.rs": "pub struct Problem;\nfn f(_: crate::units::Cm) {}\n",
            }
        )
        self.assertEqual(code, 1, out)
        self.assertIn("cycle: units, validate", out)

    def test_a_folder_reexport_resolves_to_its_submodule(self):
        code, out = run(
            {
                "lib.rs": "pub mod render;\npub mod report;\n",
                "render/mod.rs": "mod camera;\npub use camera::View;\n",
                "render/camera.rs": "pub struct View;\n",
                "report/mod.rs": "use crate::render::View;\n",
            }
        )
        self.assertEqual(code, 0, out)
        code, out = run(
            {
                "lib.rs": "pub mod render;\npub mod report;\n",
                "render/mod.rs": "mod camera;\npub use camera::View;\n",
                "render/camera.rs": "pub struct View;\nfn f() { crate::report::g(); }\n",
                "report/mod.rs": "use crate::render::View;\npub fn g() {}\n",
            }
        )
        self.assertEqual(code, 1, out)
        self.assertIn("cycle: render, report", out)
        self.assertIn("render -> report  (render/camera.rs:2)", out)


if __name__ == "__main__":
    unittest.main()
