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
