"""Flask-WTF forms (each carries its CSRF token)."""

from __future__ import annotations

from flask_wtf import FlaskForm
from wtforms import PasswordField, SelectField, StringField
from wtforms.validators import DataRequired, Length

from dataset.services.users import MAX_PASSWORD, MIN_PASSWORD
from dataset.tables import Role


class LoginForm(FlaskForm):
    name = StringField("User name", validators=[DataRequired(), Length(max=64)])
    password = PasswordField("Password", validators=[DataRequired(), Length(max=MAX_PASSWORD)])


class LogoutForm(FlaskForm):
    pass


class CreateUserForm(FlaskForm):
    name = StringField("User name", validators=[DataRequired(), Length(max=64)])
    role = SelectField("Role", choices=[r.value for r in Role])
    password = PasswordField("Password", validators=[DataRequired(), Length(min=MIN_PASSWORD, max=MAX_PASSWORD)])
