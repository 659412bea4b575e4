"""Shader files: the include/define preprocessor (no GL needed) and compile errors (EGL)."""

from __future__ import annotations

import pytest

from viewer.gpu.programs import ProgramLibrary, ShaderError, compile_program, preprocess, stages_in


def write(folder, name, text):
    path = folder / name
    path.write_text(text)
    return path


def test_includes_and_defines_are_expanded_once_with_line_numbers(tmp_path):
    write(tmp_path, "common.glsl", "float half_of(float x) { return 0.5 * x; }\n")
    write(tmp_path, "colour.glsl", '#include "common.glsl"\nvec3 grey() { return vec3(half_of(1.0)); }\n')
    program = write(tmp_path, "flat.glsl", "#version 330\n#if defined FRAGMENT_SHADER\n"
                    '#include "colour.glsl"\n#include "common.glsl"\nout vec4 c;\n'
                    "void main() { c = vec4(grey() * SCALE, 1.0); }\n#endif\n")
    source = preprocess(program, "FRAGMENT_SHADER", {"SCALE": 2.0, "FAST": True}, search=(tmp_path,))
    lines = source.text.splitlines()
    assert lines[0].startswith("#version 430")
    assert "#define FRAGMENT_SHADER" in lines and "#define SCALE 2.0" in lines and "#define FAST 1" in lines
    assert source.text.count("float half_of") == 1          # included twice, expanded once
    assert [p.name for p in source.files] == ["flat.glsl", "colour.glsl", "common.glsl"]
    assert "#line 4 0" in lines                              # back in flat.glsl after its first include
    assert "#line 200001 2" in lines                         # common.glsl, file 2: line + 2 * stride
    assert stages_in(program) == ["FRAGMENT_SHADER"]


def test_a_missing_include_names_the_file_and_line(tmp_path):
    program = write(tmp_path, "p.glsl", '#if defined VERTEX_SHADER\n\n#include "nowhere.glsl"\n#endif\n')
    with pytest.raises(ShaderError, match=r'p\.glsl:3: #include "nowhere\.glsl": no such file'):
        preprocess(program, "VERTEX_SHADER", search=(tmp_path,))


def test_an_include_cycle_is_reported(tmp_path):
    write(tmp_path, "a.glsl", '#include "b.glsl"\n')
    write(tmp_path, "b.glsl", '#include "a.glsl"\n')
    with pytest.raises(ShaderError, match="cycle"):
        preprocess(tmp_path / "a.glsl", "VERTEX_SHADER", search=(tmp_path,))


@pytest.fixture(scope="session")
def ctx(gl_context):
    return gl_context


PASS_THROUGH = ("#if defined VERTEX_SHADER\nin vec2 in_position;\n"
                "void main() { gl_Position = vec4(in_position, 0.0, 1.0); }\n"
                "#elif defined FRAGMENT_SHADER\n#include \"tint.glsl\"\nout vec4 c;\n"
                "void main() { c = vec4(tint(), 1.0); }\n#endif\n")


def test_compile_errors_point_at_the_file_and_line_that_is_wrong(ctx, tmp_path):
    write(tmp_path, "tint.glsl", "vec3 tint() {\n    return vec3(1.0)\n}\n")   # missing ';' on line 2
    program = write(tmp_path, "pass.glsl", PASS_THROUGH)
    with pytest.raises(ShaderError) as error:
        compile_program(ctx, program, search=(tmp_path,))
    message = str(error.value)
    assert "pass.glsl: shader compile (fragment shader) failed" in message
    assert "tint.glsl:3:" in message or "tint.glsl:2:" in message   # compilers report ';' here or after


def test_reload_keeps_the_last_program_that_compiled(ctx, tmp_path):
    write(tmp_path, "tint.glsl", "vec3 tint() { return vec3(1.0, 0.5, 0.25); }\n")
    write(tmp_path, "pass.glsl", PASS_THROUGH)
    library = ProgramLibrary(ctx, tmp_path)
    first = library.get("pass")
    write(tmp_path, "tint.glsl", "vec3 tint() { return undefined_name; }\n")
    with pytest.raises(ShaderError, match="undefined_name"):
        library.reload()
    assert library.get("pass") is first
    write(tmp_path, "tint.glsl", "vec3 tint() { return vec3(0.0); }\n")
    library.reload()
    assert library.get("pass") is not first
    library.release()
