from avard.daemon import cli


def test_no_command_prints_help_and_fails(capsys):
    assert cli.main([]) == 2
    assert "COMMAND" in capsys.readouterr().err


def test_every_command_has_help_and_the_top_help_renders(capsys):
    parser = cli.build_parser()
    text = " ".join(parser.format_help().split())  # argparse wraps lines
    for name in ("analyze", "simulate", "explain", "run", "check-config", "watch", "record",
                 "keys", "demo"):
        assert name in text
    # a percent sign in a command's HELP must reach the user literally
    assert "68 % intervals" in text


def test_a_command_imports_only_its_own_module():
    import subprocess
    import sys

    code = (
        "import sys; from avard.daemon import cli; "
        "p = cli.build_parser('check-config'); "
        "print(sorted(m for m in sys.modules if m.startswith('avard.daemon.commands.')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "['avard.daemon.commands.check_config']"


def test_an_unknown_command_is_refused_with_the_list(capsys):
    import pytest

    with pytest.raises(SystemExit) as exc:
        cli.main(["no-such-command"])
    assert exc.value.code == 2
    assert "analyze" in capsys.readouterr().err
