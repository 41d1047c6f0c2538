"""Settings as command-line options: a settings field carries the text of its option
(:func:`option`), and :func:`add_option` makes the option from the field, its type read
from the annotation, so that help, choices and types are written once, beside the
setting (the task settings of facelib/tasks/settings.py, the training recipes' of
facelib/training/settings.py, registration.Registration)."""

from __future__ import annotations

import argparse
import functools
import typing
from dataclasses import field, fields


def option(default, help=None, choices=None, flag=None):
    """A settings field with the text of its command-line option and, where it has
    them, its choices and its option's name (``flag``, default ``--field-name``): the
    one place any of them is written.  A field of the same name in a related settings
    class, written without them, has the same (:func:`option_text`)."""
    given = (("help", help), ("choices", choices), ("flag", flag))
    return field(default=default, metadata={k: v for k, v in given if v is not None})


def option_text(cls, name, key, family=()):
    """The ``key`` ("help", "choices" or "flag") of the field ``name`` of the settings
    class ``cls``: its own or its bases', else that of the first class of ``family``
    that gives one for a field of that name; None if none does."""
    if name not in {f.name for f in fields(cls)}:
        raise ValueError(f"{cls.__name__} has no setting {name!r}")
    for klass in (*cls.__mro__, *family):
        found = getattr(klass, "__dataclass_fields__", {}).get(name)
        if found is not None and key in found.metadata:
            return found.metadata[key]
    return None


def shown(value):
    """A setting's value as the command line spells it (None: 'none')."""
    return "none" if value is None else value


def field_type(cls, name):
    """(type, optional) of the field ``name`` of the dataclass ``cls``, read from its
    annotation: ``int | None`` -> (int, True), ``float`` -> (float, False)."""
    hint = _type_hints(cls)[name]
    args = [a for a in typing.get_args(hint) if a is not type(None)]
    return (args[0] if args else hint), type(None) in typing.get_args(hint)


@functools.cache
def _type_hints(cls):
    """typing.get_type_hints(cls), read once per class (the annotations are strings,
    evaluated on every call: most of the command line's start-up)."""
    return typing.get_type_hints(cls)


def converter(base, optional, name):
    """An argparse type for a field of type ``base`` (int, float, str; ``optional``:
    'none' is None); anything else must parse as the field's type."""
    if base not in (int, float, str):
        raise TypeError(f"no option type for a field of type {base!r}")

    def convert(text):
        if optional and text.lower() == "none":
            return None
        try:
            return base(text)
        except ValueError:
            what = "text" if base is str else base.__name__
            raise argparse.ArgumentTypeError(
                f"--{name.replace('_', '-')} must be {what}"
                f"{' or none' if optional else ''}, got {text!r}"
            ) from None

    convert.__name__ = base.__name__
    return convert


def add_option(group, cls, name, default_text, family=(), aliases=()):
    """The option of the field ``name`` of the settings class ``cls`` on the argparse
    ``group``: its flag, help and choices those of the field (:func:`option`), the help
    ending in ``(default_text)``, its type the field's (a bool field: ``--x`` /
    ``--no-x``; 'none' for None where the field allows it).  An option not given leaves
    no attribute, so that the settings' own default applies."""
    text = option_text(cls, name, "help", family)
    if text is None:
        raise ValueError(f"{cls.__name__}.{name} has no help (options.option)")
    flag = option_text(cls, name, "flag", family) or "--" + name.replace("_", "-")
    kwargs = dict(dest=name, default=argparse.SUPPRESS, help=f"{text} ({default_text})")
    base, optional = field_type(cls, name)
    if base is bool:
        group.add_argument(
            flag, *aliases, action=argparse.BooleanOptionalAction, **kwargs
        )
        return
    choices = option_text(cls, name, "choices", family)
    if choices is not None and optional:
        choices = (*choices, None)
    group.add_argument(
        flag,
        *aliases,
        type=converter(base, optional, name),
        choices=choices,
        metavar=name.upper() if choices is None else None,
        **kwargs,
    )
