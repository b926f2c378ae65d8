"""The guide of a person's photos (``robot: photos``): the next shots as a static web page
(:mod:`scenebot.guide.page`, ``round_XXX/guide/index.html``) and a small web server that
shows it to a phone and takes the photos back into the next round's inbox
(:mod:`scenebot.guide.serve`, ``scenebot guide serve``)."""
